#include "io/mesh_export.hpp"

#include "core/error.hpp"
#include "io/output_file.hpp"

#include <algorithm>
#include <charconv>
#include <cstring>
#include <memory>

namespace tetstream::io {

namespace {

constexpr std::size_t kPointChunk = std::size_t(1) << 16;

bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

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

void write_vtu(const TetReader& r, OutputFile& f, const MeshExportOptions& o) {
  const std::uint64_t n = r.point_count(), t = r.tet_count();
  const bool f32 = r.header().coord_type == CoordType::kFloat32;
  // Appended blocks, each a UInt64 byte count then the data; offsets from the '_'.
  const std::uint64_t sizes[5] = {8 * n, 3 * n * (f32 ? 4 : 8), 32 * t, 8 * t, t};
  std::uint64_t offsets[5], at = 0;
  for (int b = 0; b < 5; ++b) offsets[b] = at, at += 8 + sizes[b];
  std::string xml =
      "<?xml version=\"1.0\"?>\n"
      "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n"
      "  <UnstructuredGrid>\n";
  xml += "    <Piece NumberOfPoints=\"" + std::to_string(n) + "\" NumberOfCells=\"" + std::to_string(t) + "\">\n";
  xml += "      <PointData>\n        <DataArray type=\"Int64\" Name=\"original_id\" format=\"appended\" offset=\"" +
         std::to_string(offsets[0]) + "\"/>\n      </PointData>\n";
  xml += std::string("      <Points>\n        <DataArray type=\"") + (f32 ? "Float32" : "Float64") +
         "\" Name=\"Points\" NumberOfComponents=\"3\" format=\"appended\" offset=\"" + std::to_string(offsets[1]) +
         "\"/>\n      </Points>\n";
  xml += "      <Cells>\n";
  xml += "        <DataArray type=\"Int64\" Name=\"connectivity\" format=\"appended\" offset=\"" +
         std::to_string(offsets[2]) + "\"/>\n";
  xml += "        <DataArray type=\"Int64\" Name=\"offsets\" format=\"appended\" offset=\"" + std::to_string(offsets[3]) +
         "\"/>\n";
  xml += "        <DataArray type=\"UInt8\" Name=\"types\" format=\"appended\" offset=\"" + std::to_string(offsets[4]) +
         "\"/>\n";
  xml += "      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n  <AppendedData encoding=\"raw\">\n   _";
  f.write(xml);
  auto block = [&f](std::uint64_t bytes) { f.write(&bytes, 8); };

  // The points pass writes the ids, then the coordinates straight from the records.
  block(sizes[0]);
  std::vector<std::uint64_t> ids(kPointChunk);
  for (std::uint64_t first = 0; first < n; first += kPointChunk) {
    const std::size_t k = std::size_t(std::min<std::uint64_t>(kPointChunk, n - first));
    r.read_points(first, k, nullptr, ids.data());
    f.write(ids.data(), 8 * k);
  }
  block(sizes[1]);
  const auto records = r.point_records();
  const std::size_t rec = r.header().point_record_bytes(), cb = f32 ? 12 : 24;
  for (std::uint64_t first = 0; first < n; first += kPointChunk) {
    const std::size_t k = std::size_t(std::min<std::uint64_t>(kPointChunk, n - first));
    char* p = f.reserve(k * cb);
    const std::uint8_t* src = records.data() + first * rec;
    for (std::size_t i = 0; i < k; ++i) std::memcpy(p + i * cb, src + i * rec, cb);
    f.advance(k * cb);
    if (o.on_points) o.on_points(k);
  }
  // The tets pass; offsets and types follow from the count.
  block(sizes[2]);
  for_each_frame(r, o, [&](const std::vector<std::uint64_t>& labels) { f.write(labels.data(), 8 * labels.size()); });
  block(sizes[3]);
  for (std::uint64_t i = 1; i <= t; ++i) {
    const std::uint64_t end = 4 * i;
    f.write(&end, 8);
  }
  block(sizes[4]);
  const std::uint8_t tetra = 10;  // VTK_TETRA
  for (std::uint64_t i = 0; i < t; ++i) f.write(&tetra, 1);
  f.write("\n  </AppendedData>\n</VTKFile>\n");
}

void write_medit(const TetReader& r, OutputFile& f, const MeshExportOptions& o) {
  Text out(f);
  out.s("MeshVersionFormatted 2\n\nDimension 3\n\nVertices\n").u(r.point_count()).c('\n');
  for_each_point_chunk(r, o, [&](const double* xyz, const std::uint64_t*, std::size_t k) {
    for (std::size_t i = 0; i < k; ++i) out.d(xyz[3 * i]).c(' ').d(xyz[3 * i + 1]).c(' ').d(xyz[3 * i + 2]).s(" 0\n");
  });
  out.s("\nTetrahedra\n").u(r.tet_count()).c('\n');
  for_each_frame(r, o, [&](const std::vector<std::uint64_t>& l) {
    for (std::size_t i = 0; i < l.size(); i += 4) {
      out.u(l[i] + 1).c(' ').u(l[i + 1] + 1).c(' ').u(l[i + 2] + 1).c(' ').u(l[i + 3] + 1).s(" 0\n");
    }
  });
  out.s("\nEnd\n");
}

void write_gmsh(const TetReader& r, OutputFile& f, const MeshExportOptions& o) {
  Text out(f);
  const std::uint64_t n = r.point_count(), t = r.tet_count();
  out.s("$MeshFormat\n4.1 0 8\n$EndMeshFormat\n");
  // One node block on volume entity 1: tags 1..N, then their coordinates.
  out.s("$Nodes\n1 ").u(n).s(" 1 ").u(n).c('\n').s("3 1 0 ").u(n).c('\n');
  for (std::uint64_t i = 1; i <= n; ++i) out.u(i).c('\n');
  for_each_point_chunk(r, o, [&](const double* xyz, const std::uint64_t*, std::size_t k) {
    for (std::size_t i = 0; i < k; ++i) out.d(xyz[3 * i]).c(' ').d(xyz[3 * i + 1]).c(' ').d(xyz[3 * i + 2]).c('\n');
  });
  out.s("$EndNodes\n$Elements\n1 ").u(t).s(" 1 ").u(t).c('\n').s("3 1 4 ").u(t).c('\n');
  std::uint64_t tag = 1;
  for_each_frame(r, o, [&](const std::vector<std::uint64_t>& l) {
    for (std::size_t i = 0; i < l.size(); i += 4) {
      out.u(tag++).c(' ').u(l[i] + 1).c(' ').u(l[i + 1] + 1).c(' ').u(l[i + 2] + 1).c(' ').u(l[i + 3] + 1).c('\n');
    }
  });
  out.s("$EndElements\n");
}

void write_tetgen_node(const TetReader& r, OutputFile& f, const MeshExportOptions& o) {
  Text out(f);
  out.u(r.point_count()).s(" 3 0 0\n");
  std::uint64_t index = 1;
  for_each_point_chunk(r, o, [&](const double* xyz, const std::uint64_t*, std::size_t k) {
    for (std::size_t i = 0; i < k; ++i) {
      out.u(index++).c(' ').d(xyz[3 * i]).c(' ').d(xyz[3 * i + 1]).c(' ').d(xyz[3 * i + 2]).c('\n');
    }
  });
}

void write_tetgen_ele(const TetReader& r, OutputFile& f, const MeshExportOptions& o) {
  Text out(f);
  out.u(r.tet_count()).s(" 4 0\n");
  std::uint64_t index = 1;
  for_each_frame(r, o, [&](const std::vector<std::uint64_t>& l) {
    for (std::size_t i = 0; i < l.size(); i += 4) {
      out.u(index++).c(' ').u(l[i] + 1).c(' ').u(l[i + 1] + 1).c(' ').u(l[i + 2] + 1).c(' ').u(l[i + 3] + 1).c('\n');
    }
  });
}

}  // namespace

MeshFormat mesh_format_for(const std::string& path) {
  if (ends_with(path, ".vtu")) return MeshFormat::kVtu;
  if (ends_with(path, ".mesh")) return MeshFormat::kMedit;
  if (ends_with(path, ".msh")) return MeshFormat::kGmsh;
  if (ends_with(path, ".node") || ends_with(path, ".ele")) return MeshFormat::kTetgen;
  throw UsageError(path + ": unknown mesh format (use .vtu, .mesh, .msh or .node)");
}

const char* mesh_format_name(MeshFormat format) {
  switch (format) {
    case MeshFormat::kVtu: return "VTK XML unstructured grid (.vtu)";
    case MeshFormat::kMedit: return "Medit (.mesh)";
    case MeshFormat::kGmsh: return "Gmsh 4.1 (.msh)";
    case MeshFormat::kTetgen: return "TetGen (.node + .ele)";
  }
  return "?";
}

MeshExportResult export_mesh(const TetReader& reader, const std::string& path, MeshFormat format,
                             const MeshExportOptions& options) {
  reader.verify_points();
  MeshExportResult result;
  auto finish = [&result](OutputFile& f) {
    result.bytes += f.offset();
    f.commit();
    result.files.push_back(f.path());
  };
  if (format == MeshFormat::kTetgen) {
    const std::string base = path.substr(0, path.rfind('.'));
    OutputFile node(base + ".node"), ele(base + ".ele");
    write_tetgen_node(reader, node, options);
    write_tetgen_ele(reader, ele, options);
    finish(node);
    finish(ele);
    return result;
  }
  OutputFile f(path);
  switch (format) {
    case MeshFormat::kVtu: write_vtu(reader, f, options); break;
    case MeshFormat::kMedit: write_medit(reader, f, options); break;
    case MeshFormat::kGmsh: write_gmsh(reader, f, options); break;
    case MeshFormat::kTetgen: break;
  }
  finish(f);
  return result;
}

}  // namespace tetstream::io
