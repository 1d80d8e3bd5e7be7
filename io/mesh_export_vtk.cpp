// Legacy VTK (DataFile Version 5.1) UNSTRUCTURED_GRID, ASCII or big-endian binary.
// Version 5.1 stores cells as OFFSETS + CONNECTIVITY arrays of vtktypeint64, so labels
// past 2^31 are written as they are (version 4.2 has 32-bit cell lists only).
#include "io/mesh_export_detail.hpp"

namespace tetstream::io::mesh_detail {

namespace {

// Values of one array in the file's encoding: text, one value (or row) a line, or
// big-endian binary; end() closes the binary block with its newline.
class VtkArray {
 public:
  VtkArray(OutputFile& f, bool binary) : f_(f), text_(f), binary_(binary) {}
  template <class T>
  void row(const T* v, std::size_t k) {
    if (binary_) {
      char* p = f_.reserve(sizeof(T) * k);
      for (std::size_t i = 0; i < k; ++i) put_big_endian(p + sizeof(T) * i, v[i]);
      f_.advance(sizeof(T) * k);
      return;
    }
    for (std::size_t i = 0; i < k; ++i) {
      if constexpr (std::is_floating_point_v<T>)
        text_.d(v[i]);
      else
        text_.u(std::uint64_t(v[i]));
      text_.c(i + 1 == k ? '\n' : ' ');
    }
  }
  void end() {
    if (binary_) text_.c('\n');
  }

 private:
  OutputFile& f_;
  Text text_;
  bool binary_;
};

}  // namespace

void write_vtk(const TetReader& r, OutputFile& f, const MeshExportOptions& o) {
  const std::uint64_t n = r.point_count(), t = r.tet_count();
  Text out(f);
  VtkArray array(f, o.binary);
  out.s("# vtk DataFile Version 5.1\ntetstream Delaunay tetrahedra\n").s(o.binary ? "BINARY\n" : "ASCII\n");
  out.s("DATASET UNSTRUCTURED_GRID\nPOINTS ").u(n).s(" double\n");
  for_each_point_chunk(r, o, [&](const double* xyz, const std::uint64_t*, std::size_t k) {
    for (std::size_t i = 0; i < k; ++i) array.row(xyz + 3 * i, 3);
  });
  array.end();
  out.s("CELLS ").u(t + 1).c(' ').u(4 * t).s("\nOFFSETS vtktypeint64\n");
  for (std::uint64_t i = 0; i <= t; ++i) {
    const std::int64_t end = std::int64_t(4 * i);
    array.row(&end, 1);
  }
  array.end();
  out.s("CONNECTIVITY vtktypeint64\n");
  std::vector<std::int64_t> cells;
  for_each_frame(r, o, [&](const std::vector<std::uint64_t>& l) {
    cells.assign(l.begin(), l.end());
    for (std::size_t i = 0; i < cells.size(); i += 4) array.row(cells.data() + i, 4);
  });
  array.end();
  out.s("CELL_TYPES ").u(t).c('\n');
  const std::int32_t tetra = 10;  // VTK_TETRA
  for (std::uint64_t i = 0; i < t; ++i) array.row(&tetra, 1);
  array.end();
  out.s("POINT_DATA ").u(n).s("\nSCALARS original_id vtktypeint64 1\nLOOKUP_TABLE default\n");
  std::vector<std::uint64_t> ids(kPointChunk);
  for (std::uint64_t first = 0; first < n; first += kPointChunk) {
    const std::size_t k = std::size_t(std::min<std::uint64_t>(kPointChunk, n - first));
    r.read_points(first, k, nullptr, ids.data());
    for (std::size_t i = 0; i < k; ++i) {
      const std::int64_t id = std::int64_t(ids[i]);
      array.row(&id, 1);
    }
  }
  array.end();
  for (const PointDataArray& a : o.point_data) {
    out.s("SCALARS ").s(a.name).s(" double 1\nLOOKUP_TABLE default\n");
    for (std::uint64_t i = 0; i < n; ++i) array.row(a.values.data() + i, 1);
    array.end();
  }
}

}  // namespace tetstream::io::mesh_detail
