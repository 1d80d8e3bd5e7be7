// .xdmf: the light data (XDMF 3 XML) in PATH, the heavy data in BASE.h5 beside it,
// written with HDF5 in hyperslabs of one point chunk or one frame at a time.
//
// BASE.h5 is made the way OutputFile makes its files: BASE.h5.partial is claimed
// (OutputClaim: no link followed, locked against a second job), written, flushed,
// synced, and renamed only after the .xdmf is complete; on failure it is removed.
// Built only with TETSTREAM_HDF5 (io/CMakeLists.txt); mesh_export_xdmf_none.cpp otherwise.
#include "core/error.hpp"
#include "io/hdf5_detail.hpp"
#include "io/mesh_export_detail.hpp"

#include <cerrno>
#include <cstdio>
#include <sys/stat.h>
#include <unistd.h>

namespace tetstream::io::mesh_detail {

namespace {

using hdf5::Handle;

// An (rows, cols) dataset of `file_type`, written by rows.
class Dataset {
 public:
  Dataset(hid_t file, const char* name, hid_t file_type, std::uint64_t rows, hsize_t cols, const std::string& where)
      : where_(where + ":" + name), cols_(cols), set_(create(file, name, file_type, rows, cols), H5Dclose) {
    if (!set_.ok()) throw IoError(where_ + ": cannot create the dataset");
  }
  void write(hid_t memory_type, std::uint64_t first, std::uint64_t rows, const void* data) {
    if (rows == 0) return;
    const hsize_t start[2] = {hsize_t(first), 0}, count[2] = {hsize_t(rows), cols_};
    const int rank = cols_ > 1 ? 2 : 1;
    Handle file_space(H5Dget_space(set_.get()), H5Sclose);
    Handle memory_space(H5Screate_simple(rank, count, nullptr), H5Sclose);
    if (!file_space.ok() || !memory_space.ok() ||
        H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start, nullptr, count, nullptr) < 0 ||
        H5Dwrite(set_.get(), memory_type, memory_space.get(), file_space.get(), H5P_DEFAULT, data) < 0) {
      throw IoError(where_ + ": write failed (disk full?)");
    }
  }

 private:
  static hid_t create(hid_t file, const char* name, hid_t file_type, std::uint64_t rows, hsize_t cols) {
    const hsize_t dims[2] = {hsize_t(rows), cols};
    Handle space(H5Screate_simple(cols > 1 ? 2 : 1, dims, nullptr), H5Sclose);
    return space.ok() ? H5Dcreate2(file, name, file_type, space.get(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT) : -1;
  }

  std::string where_;
  hsize_t cols_;
  Handle set_;
};

// Removes BASE.h5.partial unless disarmed.
struct RemoveOnFailure {
  std::string path;
  bool armed = true;
  ~RemoveOnFailure() {
    if (armed) ::unlink(path.c_str());
  }
};

std::string file_name(const std::string& path) {
  const auto slash = path.rfind('/');
  return slash == std::string::npos ? path : path.substr(slash + 1);
}

// The file name as XML text.
std::string xml_escaped(const std::string& s) {
  std::string out;
  for (const char c : s) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

std::string xdmf_text(const std::string& h5_name, std::uint64_t n, std::uint64_t t, const MeshExportOptions& o) {
  const std::string N = std::to_string(n), T = std::to_string(t);
  auto item = [&h5_name](const std::string& dims, const char* type, const char* set) {
    return "<DataItem Dimensions=\"" + dims + "\" NumberType=\"" + type + "\" Precision=\"8\" Format=\"HDF\">" +
           h5_name + ":/" + set + "</DataItem>\n";
  };
  std::string point_data;  // (names are plain: export_mesh checked them)
  for (const PointDataArray& a : o.point_data) {
    point_data += "      <Attribute Name=\"" + a.name +
                  "\" AttributeType=\"Scalar\" Center=\"Node\">\n"
                  "        " +
                  item(N, "Float", ("point_data/" + a.name).c_str()) + "      </Attribute>\n";
  }
  return "<?xml version=\"1.0\"?>\n"
         "<Xdmf Version=\"3.0\">\n"
         "  <Domain>\n"
         "    <Grid Name=\"tetstream\" GridType=\"Uniform\">\n"
         "      <Topology TopologyType=\"Tetrahedron\" NumberOfElements=\"" +
         T +
         "\" NodesPerElement=\"4\">\n"
         "        " +
         item(T + " 4", "Int", "tets") +
         "      </Topology>\n"
         "      <Geometry GeometryType=\"XYZ\">\n"
         "        " +
         item(N + " 3", "Float", "points") +
         "      </Geometry>\n"
         "      <Attribute Name=\"original_id\" AttributeType=\"Scalar\" Center=\"Node\">\n"
         "        " +
         item(N, "Int", "original_id") + "      </Attribute>\n" + point_data +
         "    </Grid>\n"
         "  </Domain>\n"
         "</Xdmf>\n";
}

}  // namespace

void write_xdmf(const TetReader& r, const std::string& path, const MeshExportOptions& o, MeshExportResult& result) {
  const std::uint64_t n = r.point_count(), t = r.tet_count();
  const std::string base = path.substr(0, path.size() - std::string(".xdmf").size());
  const std::string h5 = base + ".h5";
  hdf5::quiet();
  OutputFile xdmf(path);  // claims PATH first: a second job on the same mesh stops here
  // BASE.h5 is a name the user did not give: an existing one that is not an earlier
  // output beside this .xdmf is theirs (a snapshot the points came from, say).
  const OutputClaim claim(h5, OutputClaim::Kind::kBeside, path);
  RemoveOnFailure cleanup{h5 + ".partial"};
  {
    // The claim holds a flock on the partial file: HDF5's own lock would conflict with it.
    Handle fapl(H5Pcreate(H5P_FILE_ACCESS), H5Pclose);
    if (!fapl.ok() || H5Pset_file_locking(fapl.get(), false, true) < 0) throw IoError(h5 + ": HDF5 setup failed");
    Handle file(H5Fcreate(cleanup.path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, fapl.get()), H5Fclose);
    if (!file.ok()) throw IoError("cannot create " + cleanup.path);
    Dataset points(file.get(), "points", H5T_IEEE_F64LE, n, 3, h5);
    Dataset ids(file.get(), "original_id", H5T_STD_I64LE, n, 1, h5);
    Dataset tets(file.get(), "tets", H5T_STD_I64LE, t, 4, h5);
    // The point data under a group of its own: a user's name cannot meet points or tets.
    if (!o.point_data.empty()) {
      Handle group(H5Gcreate2(file.get(), "point_data", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose);
      if (!group.ok()) throw IoError(h5 + ": cannot create the group point_data");
      for (const PointDataArray& a : o.point_data) {
        Dataset values(group.get(), a.name.c_str(), H5T_IEEE_F64LE, n, 1, h5 + ":point_data");
        values.write(H5T_NATIVE_DOUBLE, 0, n, a.values.data());
      }
    }
    std::uint64_t first = 0;
    for_each_point_chunk(r, o, [&](const double* xyz, const std::uint64_t* id, std::size_t k) {
      points.write(H5T_NATIVE_DOUBLE, first, k, xyz);
      ids.write(H5T_NATIVE_UINT64, first, k, id);
      first += k;
    });
    first = 0;
    for_each_frame(r, o, [&](const std::vector<std::uint64_t>& labels) {
      tets.write(H5T_NATIVE_UINT64, first, labels.size() / 4, labels.data());
      first += labels.size() / 4;
    });
    if (H5Fflush(file.get(), H5F_SCOPE_LOCAL) < 0 || !file.close())
      throw IoError(cleanup.path + ": write failed (disk full?)");
  }
  {
    // HDF5 opened the partial file by name: it must still be the claimed one.
    struct stat at {
    }, held{};
    if (::lstat(cleanup.path.c_str(), &at) != 0 || ::fstat(claim.fd(), &held) != 0 || at.st_dev != held.st_dev ||
        at.st_ino != held.st_ino)
      throw IoError(cleanup.path + ": replaced while it was written");
  }
  if (::fsync(claim.fd()) != 0) throw IoError(cleanup.path + ": fsync failed: " + std::strerror(errno));
  xdmf.write(xdmf_text(xml_escaped(file_name(h5)), n, t, o));
  if (::rename(cleanup.path.c_str(), h5.c_str()) != 0) {
    throw IoError("cannot rename " + cleanup.path + " to " + h5 + ": " + std::strerror(errno));
  }
  cleanup.armed = false;
  note_input(h5);  // a later output of this process (--json-file) never replaces it
  result.bytes += xdmf.offset();
  xdmf.commit();
  struct stat st {};
  result.bytes += ::stat(h5.c_str(), &st) == 0 ? std::uint64_t(st.st_size) : 0;
  result.files.push_back(path);
  result.files.push_back(h5);
}

}  // namespace tetstream::io::mesh_detail
