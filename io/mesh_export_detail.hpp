#pragma once
// Internals shared by the mesh writers (mesh_export.cpp, mesh_export_vtk.cpp,
// mesh_export_xdmf*.cpp): formatted text into an OutputFile, the chunked passes over a
// container's points and frames, and byte-order helpers for the big-endian formats.
#include "io/mesh_export.hpp"
#include "io/output_file.hpp"
#include "io/tet_reader.hpp"

#include <algorithm>
#include <bit>
#include <charconv>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

namespace tetstream::io::mesh_detail {

inline constexpr std::size_t kPointChunk = std::size_t(1) << 16;

// Formatted text straight into the output buffer.
class Text {
 public:
  explicit Text(OutputFile& f) : f_(f) {}
  Text& u(std::uint64_t v) {
    char* p = f_.reserve(24);
    f_.advance(std::size_t(std::to_chars(p, p + 24, v).ptr - p));
    return *this;
  }
  Text& d(double v) {
    char* p = f_.reserve(32);
    f_.advance(std::size_t(std::to_chars(p, p + 32, v).ptr - p));
    return *this;
  }
  Text& c(char ch) {
    *f_.reserve(1) = ch;
    f_.advance(1);
    return *this;
  }
  Text& s(std::string_view str) {
    f_.write(str);
    return *this;
  }

 private:
  OutputFile& f_;
};

// Calls fn(xyz, ids, n) for consecutive chunks of points in label order.
template <class F>
void for_each_point_chunk(const TetReader& r, const MeshExportOptions& o, F fn) {
  std::vector<double> xyz(3 * kPointChunk);
  std::vector<std::uint64_t> ids(kPointChunk);
  for (std::uint64_t first = 0; first < r.point_count(); first += kPointChunk) {
    const std::size_t n = std::size_t(std::min<std::uint64_t>(kPointChunk, r.point_count() - first));
    r.read_points(first, n, xyz.data(), ids.data());
    fn(xyz.data(), ids.data(), n);
    if (o.on_points) o.on_points(n);
  }
}

// Calls fn(labels) for each frame's tets (4 labels each), in stored order.
template <class F>
void for_each_frame(const TetReader& r, const MeshExportOptions& o, F fn) {
  std::vector<std::uint64_t> labels;
  for (std::uint64_t k = 0; k < r.frame_count(); ++k) {
    r.read_frame(k, labels);
    fn(labels);
    if (o.on_tets) o.on_tets(labels.size() / 4);
  }
}

// A value's bytes in big-endian order (legacy VTK binary).
template <class T>
void put_big_endian(char* out, T value) {
  static_assert(sizeof(T) == 8 || sizeof(T) == 4);
  using U = std::conditional_t<sizeof(T) == 8, std::uint64_t, std::uint32_t>;
  U bits = std::bit_cast<U>(value);
  if constexpr (std::endian::native == std::endian::little) {
    if constexpr (sizeof(T) == 8)
      bits = __builtin_bswap64(bits);
    else
      bits = __builtin_bswap32(bits);
  }
  std::memcpy(out, &bits, sizeof(T));
}

// The writers of the other files (mesh_export_vtk.cpp, mesh_export_xdmf*.cpp).
void write_vtk(const TetReader& r, OutputFile& f, const MeshExportOptions& o);
// Writes BASE.xdmf and its heavy data BASE.h5; adds both to `result`.
void write_xdmf(const TetReader& r, const std::string& path, const MeshExportOptions& o, MeshExportResult& result);

}  // namespace tetstream::io::mesh_detail
