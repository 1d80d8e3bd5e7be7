#include "io/las_attributes.hpp"

#include "core/error.hpp"
#include "io/point_detail.hpp"

#include <sys/stat.h>

#include <algorithm>
#include <limits>

namespace tetstream::io {

std::vector<PointDataArray> las_point_data(const TetReader& reader, const std::string& las_path,
                                           const PointReadOptions& read) {
  const std::string why = " (convert --las-attributes reads the container's input again)";
  struct stat st {};
  if (is_std_stream(las_path))
    throw InputError("the container's input was standard input: it cannot be read again" + why);
  // A relative name is relative to where `run` ran: here, else beside the container.
  std::string path = las_path;
  if (::stat(path.c_str(), &st) != 0 && !path.empty() && path.front() != '/') {
    const std::size_t slash = reader.path().rfind('/');
    if (slash != std::string::npos) path = reader.path().substr(0, slash + 1) + las_path;
  }
  if (::stat(path.c_str(), &st) != 0) throw InputError(las_path + ": the container's input is gone" + why);
  PointReadOptions options = read;
  options.format = PointFormat::kLas;
  auto src = std::make_unique<ByteSource>(path);
  if (src->ensure(4) < 4 || std::memcmp(src->data(), "LASF", 4) != 0)
    throw InputError(path + ": not a LAS file: --las-attributes needs a container made from LAS input");

  // Each container point's label by its original id; its coordinates by label.
  const std::uint64_t n = reader.point_count();
  const std::uint64_t none = std::numeric_limits<std::uint64_t>::max();
  std::vector<double> xyz(3 * n);
  std::vector<std::uint64_t> ids(n);
  if (n > 0) reader.read_points(0, std::size_t(n), xyz.data(), ids.data());
  std::uint64_t inputs = reader.header().input_count;
  if (inputs == 0)
    for (const auto id : ids) inputs = std::max(inputs, id + 1);
  std::vector<std::uint64_t> label_of(inputs, none);
  for (std::uint64_t l = 0; l < n; ++l) {
    if (ids[l] >= inputs)
      throw InputError(reader.path() + ": point " + std::to_string(l) + " has original id " + std::to_string(ids[l]) +
                       " past the input's " + std::to_string(inputs) + " points");
    label_of[ids[l]] = l;
  }

  std::vector<PointDataArray> out(4);
  out[0].name = "intensity", out[1].name = "classification", out[2].name = "return_number", out[3].name = "gps_time";
  for (auto& a : out) a.values.assign(n, 0.0);
  std::vector<detail::LasFields> fields;
  auto las = detail::open_las(std::move(src), options, [&fields](const detail::LasFields& f) { fields.push_back(f); });
  const std::string changed = path + ": changed since the container was made";
  constexpr std::size_t kChunk = std::size_t(1) << 16;
  std::vector<double> chunk(3 * kChunk);
  std::uint64_t id = 0;
  while (std::size_t k = las->read(chunk.data(), kChunk)) {
    for (std::size_t i = 0; i < k; ++i, ++id) {
      if (id >= inputs)
        throw InputError(changed + ": it has more than the " + std::to_string(inputs) +
                         " points the container was made from");
      const std::uint64_t l = label_of[id];
      if (l == none) continue;  // a duplicate merged into an earlier point
      if (chunk[3 * i] != xyz[3 * l] || chunk[3 * i + 1] != xyz[3 * l + 1] || chunk[3 * i + 2] != xyz[3 * l + 2])
        throw InputError(changed + ": point " + std::to_string(id) + " (" + las->location(id) +
                         ") is not where the container has it");
      const detail::LasFields& f = fields[i];
      out[0].values[l] = f.intensity;
      out[1].values[l] = f.classification;
      out[2].values[l] = f.return_number;
      out[3].values[l] = f.gps_time;
    }
    fields.clear();
  }
  if (id != inputs)
    throw InputError(changed + ": it has " + std::to_string(id) +
                     " points (after its filters), the container was made from " + std::to_string(inputs));
  // Formats 0 and 2 have no GPS time ("las 1.2 point format 2").
  const std::string& name = las->format_name();
  const int format = std::stoi(name.substr(name.rfind(' ') + 1));
  if (format == 0 || format == 2) out.pop_back();
  return out;
}

}  // namespace tetstream::io
