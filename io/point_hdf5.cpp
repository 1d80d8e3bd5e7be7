// HDF5 point datasets (Gadget-2/3, SWIFT, h5py): rank-2 arrays of shape (N, 3),
// float32 or float64, read as hyperslabs of at most the caller's chunk of rows, which
// HDF5 converts straight into the caller's doubles (float to double is exact). Memory
// is the caller's chunk plus HDF5's own caches (about 1 MiB), whatever the file size.
// The points of several --dataset are read one dataset after another, so a point's
// index is its row plus the rows of the datasets before it.
//
// Built only with TETSTREAM_HDF5 (io/CMakeLists.txt); point_hdf5_none.cpp otherwise.
#include "io/hdf5_detail.hpp"
#include "io/point_detail.hpp"
#include "io/output_file.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cerrno>
#include <unistd.h>
#include <vector>

namespace tetstream::io {
namespace {

using hdf5::Handle;
using hdf5::quiet;

Handle open_file(const std::string& path) {
  quiet();
  if (::access(path.c_str(), R_OK) != 0) throw IoError("cannot open " + path + ": " + std::strerror(errno));
  io::note_input(path);
  Handle f(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (!f.ok())
    throw InputError::at_byte(path, 0, "not a readable HDF5 file (no HDF5 signature, or truncated or damaged)");
  return f;
}

// Shape and type of an open dataset; "" when it is an (N, 3) float array, else why not.
std::string point_array_problem(hid_t ds, std::uint64_t& rows, std::string& type) {
  Handle space(H5Dget_space(ds), H5Sclose);
  Handle t(H5Dget_type(ds), H5Tclose);
  if (!space.ok() || !t.ok()) return "unreadable dataspace or type";
  const int rank = H5Sget_simple_extent_ndims(space.get());
  hsize_t dims[H5S_MAX_RANK] = {};
  if (rank > 0) H5Sget_simple_extent_dims(space.get(), dims, nullptr);
  if (rank != 2 || dims[1] != 3) {
    std::string shape = "(";
    for (int i = 0; i < rank; ++i) shape += (i ? ", " : "") + std::to_string(dims[i]);
    return "shape " + shape + (rank == 1 ? ",)" : ")") + " is not (N, 3)";
  }
  const std::size_t size = H5Tget_size(t.get());
  if (H5Tget_class(t.get()) != H5T_FLOAT || (size != 4 && size != 8)) return "type is not float32 or float64";
  rows = dims[0];
  type = size == 4 ? "float32" : "float64";
  return "";
}

herr_t visit_link(hid_t group, const char* name, const H5L_info_t* info, void* data) {
  if (info->type != H5L_TYPE_HARD) return 0;
  Handle ds(H5Dopen2(group, name, H5P_DEFAULT), H5Dclose);  // fails (quietly) on groups
  if (!ds.ok()) return 0;
  Hdf5PointDataset d;
  if (point_array_problem(ds.get(), d.rows, d.type).empty()) {
    d.path = std::string("/") + name;
    static_cast<std::vector<Hdf5PointDataset>*>(data)->push_back(std::move(d));
  }
  return 0;
}

std::vector<Hdf5PointDataset> list_datasets(hid_t file) {
  std::vector<Hdf5PointDataset> found;
  H5Lvisit(file, H5_INDEX_NAME, H5_ITER_INC, visit_link, &found);
  return found;
}

std::string candidates(const std::vector<Hdf5PointDataset>& list) {
  if (list.empty()) return "it has no (N, 3) float dataset";
  std::string s = "its (N, 3) datasets: ";
  for (std::size_t i = 0; i < list.size() && i < 8; ++i)
    s += (i ? ", " : "") + list[i].path + " (" + std::to_string(list[i].rows) + " " + list[i].type + ")";
  if (list.size() > 8) s += ", ...";
  return s;
}

// The index of the first component of `path` that does not exist in `file` (1 for
// "/A/B" when /A is missing); 0 when the whole path exists.
std::size_t first_missing(hid_t file, const std::string& path) {
  std::size_t component = 0, pos = 0;
  while (pos != std::string::npos) {
    const std::size_t next = path.find('/', pos + 1);
    const std::string prefix = path.substr(0, next);
    ++component;
    if (!prefix.empty() && prefix != "/" && H5Lexists(file, prefix.c_str(), H5P_DEFAULT) <= 0) return component;
    pos = next;
  }
  return 0;
}

struct Dataset {
  std::string path;
  Handle handle;
  std::uint64_t rows = 0, first = 0;  // rows, and the index of its first point
  std::size_t scalar = 8;
};

class Hdf5PointReader final : public PointReader {
 public:
  Hdf5PointReader(const std::string& path, std::vector<std::string> names, bool one_of_many) : file_(open_file(path)) {
    source_name_ = path;
    if (names.empty()) {
      const auto list = list_datasets(file_.get());
      if (list.size() != 1)
        throw UsageError(path + ": name the dataset to read with --dataset (" + candidates(list) + ")");
      names.push_back(list[0].path);
    }
    std::uint64_t total = 0;
    for (auto& name : names) {
      if (name.front() != '/') name = "/" + name;
      const std::size_t missing = first_missing(file_.get(), name);
      const std::size_t components = std::size_t(std::count(name.begin(), name.end(), '/'));
      // A snapshot file may lack a particle type's group altogether: 0 points here.
      // Said, not silent: a misspelt group would otherwise pass for a missing type.
      if (missing != 0 && one_of_many && missing < components) {
        spdlog::warn("{}: no {} in this file (its group is missing): 0 points from it", path, name);
        continue;
      }
      if (missing != 0) {
        throw InputError(path + ": dataset " + name + " not found (" + candidates(list_datasets(file_.get())) + ")");
      }
      Dataset d{name, Handle(H5Dopen2(file_.get(), name.c_str(), H5P_DEFAULT), H5Dclose)};
      if (!d.handle.ok()) throw InputError(path + ": " + name + " is not a dataset");
      std::string type;
      const std::string problem = point_array_problem(d.handle.get(), d.rows, type);
      if (!problem.empty()) throw InputError(path + ": dataset " + name + ": " + problem);
      d.scalar = type == "float32" ? 4 : 8;
      d.first = total;
      total += d.rows;
      format_name_ += (format_name_.empty() ? "hdf5 " : ", ") + name + " " + type;
      datasets_.push_back(std::move(d));
    }
    if (format_name_.empty()) format_name_ = "hdf5 (no dataset in this file)";
    count_ = total;
    if (total == 0 && !one_of_many) throw InputError(path + ": the datasets hold no points");
  }

  std::size_t read(double* xyz, std::size_t max_points) override {
    quiet();
    std::size_t n = 0;
    while (n < max_points && current_ < datasets_.size()) {
      Dataset& d = datasets_[current_];
      const std::uint64_t row = points_read_ + n - d.first;
      if (row == d.rows) {
        ++current_;
        continue;
      }
      const hsize_t k = std::min<std::uint64_t>(max_points - n, d.rows - row);
      read_rows(d, row, k, xyz + 3 * n);
      bytes_ += k * 3 * d.scalar;
      n += std::size_t(k);
    }
    const std::uint64_t first = points_read_;
    detail::check_finite(xyz, n, source_name_, [&](std::size_t i) { return location(first + i / 3); });
    points_read_ += n;
    return n;
  }

  // A hyperslab can start at any row: skipping moves the position, reading nothing.
  std::uint64_t skip(std::uint64_t n) override {
    std::uint64_t left = std::min<std::uint64_t>(n, *count_ - points_read_), done = 0;
    while (left > 0) {
      const Dataset& d = datasets_[current_];
      const std::uint64_t take = std::min(left, d.rows - (points_read_ - d.first));
      if (take == 0) {
        ++current_;
        continue;
      }
      bytes_ += take * 3 * d.scalar;
      points_read_ += take, done += take, left -= take;
    }
    return done;
  }

  std::uint64_t bytes_read() const override { return bytes_; }
  std::optional<std::uint64_t> source_size() const override {
    std::uint64_t total = 0;
    for (const auto& d : datasets_) total += d.rows * 3 * d.scalar;
    return total;
  }

  std::string location(std::uint64_t index) const override {
    for (const auto& d : datasets_)
      if (index >= d.first && index - d.first < d.rows)
        return "dataset " + d.path + " row " + std::to_string(index - d.first);
    return "point " + std::to_string(index);
  }

 private:
  // Rows [row, row + k) of d into out, converted to double by HDF5.
  void read_rows(const Dataset& d, std::uint64_t row, hsize_t k, double* out) {
    Handle file_space(H5Dget_space(d.handle.get()), H5Sclose);
    const hsize_t start[2] = {row, 0}, size[2] = {k, 3};
    Handle mem_space(H5Screate_simple(2, size, nullptr), H5Sclose);
    if (!file_space.ok() || !mem_space.ok() ||
        H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start, nullptr, size, nullptr) < 0 ||
        H5Dread(d.handle.get(), H5T_NATIVE_DOUBLE, mem_space.get(), file_space.get(), H5P_DEFAULT, out) < 0) {
      throw InputError(source_name_ + ": dataset " + d.path + " row " + std::to_string(row) +
                       ": cannot read (truncated or damaged file?)");
    }
  }

  Handle file_;
  std::vector<Dataset> datasets_;
  std::size_t current_ = 0;
  std::uint64_t bytes_ = 0;
};

}  // namespace

bool hdf5_available() { return true; }

std::vector<Hdf5PointDataset> list_hdf5_point_datasets(const std::string& path) {
  const Handle f = open_file(path);
  return list_datasets(f.get());
}

std::array<double, 3> hdf5_box_size(const std::string& path) {
  const Handle f = open_file(path);
  if (H5Aexists_by_name(f.get(), "Header", "BoxSize", H5P_DEFAULT) <= 0)
    throw UsageError(path + ": no attribute Header/BoxSize: give the box as --periodic L or Lx,Ly,Lz");
  const Handle a(H5Aopen_by_name(f.get(), "Header", "BoxSize", H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
  const Handle space(H5Aget_space(a.get()), H5Sclose);
  const hssize_t n = H5Sget_simple_extent_npoints(space.get());
  double v[3] = {0, 0, 0};
  if ((n != 1 && n != 3) || H5Aread(a.get(), H5T_NATIVE_DOUBLE, v) < 0)
    throw UsageError(path + ": Header/BoxSize is not one number or three");
  if (n == 1) v[1] = v[2] = v[0];
  return {v[0], v[1], v[2]};
}

namespace detail {
std::unique_ptr<PointReader> open_hdf5(const std::string& path, const PointReadOptions& options, bool one_of_many) {
  if (is_std_stream(path)) throw UsageError("HDF5 cannot be read from stdin: name the file");
  return std::make_unique<Hdf5PointReader>(path, options.datasets, one_of_many);
}
}  // namespace detail

}  // namespace tetstream::io
