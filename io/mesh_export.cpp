#include "io/mesh_export.hpp"

#include "core/error.hpp"
#include "io/mesh_export_detail.hpp"
#include "io/output_file.hpp"
#include "io/point_reader.hpp"

#include <zlib.h>

#include <algorithm>
#include <cctype>
#include <climits>
#include <cstring>
#include <memory>
#include <stdexcept>

namespace tetstream::io {

using namespace mesh_detail;

namespace {

bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// One appended array of a .vtu. Raw: its UInt64 byte count, then the bytes. Compressed
// (vtkZLibDataCompressor): a header of UInt64s (block count, block size, size of the
// last partial block or 0, each block's compressed size), then the zlib blocks; the
// header is written as zeros and patched once the blocks are known.
class VtuArray {
 public:
  VtuArray(OutputFile& f, std::uint64_t bytes, int level) : f_(f), bytes_(bytes), level_(level) {
    if (level_ == 0) {
      f_.write(&bytes, 8);
      return;
    }
    header_.assign(3 + (bytes + kBlock - 1) / kBlock, 0);
    header_[0] = header_.size() - 3;
    header_[1] = kBlock;
    header_[2] = bytes % kBlock;
    header_at_ = f_.offset();
    f_.write(header_.data(), 8 * header_.size());
    block_.reserve(kBlock);
  }
  void put(const void* data, std::size_t n) {
    written_ += n;
    if (level_ == 0) {
      f_.write(data, n);
      return;
    }
    const auto* p = static_cast<const unsigned char*>(data);
    while (n > 0) {
      const std::size_t k = std::min(n, kBlock - block_.size());
      block_.insert(block_.end(), p, p + k);
      p += k, n -= k;
      if (block_.size() == kBlock) compress_block();
    }
  }
  void finish() {
    if (written_ != bytes_) throw std::logic_error("vtu: an array's size differs from its header");
    if (level_ == 0) return;
    if (!block_.empty()) compress_block();
    f_.write_at(header_at_, header_.data(), 8 * header_.size());
  }

 private:
  static constexpr std::size_t kBlock = std::size_t(1) << 20;
  void compress_block() {
    uLongf size = compressBound(uLong(block_.size()));
    char* out = f_.reserve(size);
    if (compress2(reinterpret_cast<Bytef*>(out), &size, block_.data(), uLong(block_.size()), level_) != Z_OK) {
      throw IoError(f_.path() + ": zlib compression failed");
    }
    f_.advance(size);
    header_[3 + next_++] = size;
    block_.clear();
  }

  OutputFile& f_;
  std::uint64_t bytes_, written_ = 0, header_at_ = 0;
  int level_;
  std::vector<std::uint64_t> header_;
  std::vector<unsigned char> block_;
  std::size_t next_ = 0;
};

void write_vtu(const TetReader& r, OutputFile& f, const MeshExportOptions& o) {
  const std::uint64_t n = r.point_count(), t = r.tet_count();
  const bool f32 = r.header().coord_type == CoordType::kFloat32;
  const int level = o.compress_level;
  // The arrays: original_id, the point data, Points, connectivity, offsets, types;
  // `offsets` from the '_'.
  const int m = int(o.point_data.size()), P = 1 + m;
  std::vector<std::uint64_t> sizes = {8 * n};
  for (int k = 0; k < m; ++k) sizes.push_back(8 * n);
  for (std::uint64_t b : {3 * n * (f32 ? 4 : 8), 32 * t, 8 * t, t}) sizes.push_back(b);
  auto header = [&](const std::vector<std::string>& offsets) {
    std::string xml =
        "<?xml version=\"1.0\"?>\n"
        "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" "
        "header_type=\"UInt64\"";
    if (level > 0) xml += " compressor=\"vtkZLibDataCompressor\"";
    xml += ">\n  <UnstructuredGrid>\n";
    auto array = [&](int b, const std::string& attributes) {
      xml += "<DataArray " + attributes + " format=\"appended\" offset=\"" + offsets[std::size_t(b)] + "\"/>\n";
    };
    xml += "    <Piece NumberOfPoints=\"" + std::to_string(n) + "\" NumberOfCells=\"" + std::to_string(t) + "\">\n";
    xml += "      <PointData>\n        ";
    array(0, "type=\"Int64\" Name=\"original_id\"");
    for (int k = 0; k < m; ++k) {
      xml += "        ";
      array(1 + k, "type=\"Float64\" Name=\"" + o.point_data[std::size_t(k)].name + "\"");
    }
    xml += "      </PointData>\n      <Points>\n        ";
    array(P, std::string("type=\"") + (f32 ? "Float32" : "Float64") + "\" Name=\"Points\" NumberOfComponents=\"3\"");
    xml += "      </Points>\n      <Cells>\n        ";
    array(P + 1, "type=\"Int64\" Name=\"connectivity\"");
    xml += "        ";
    array(P + 2, "type=\"Int64\" Name=\"offsets\"");
    xml += "        ";
    array(P + 3, "type=\"UInt8\" Name=\"types\"");
    xml += "      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n  <AppendedData encoding=\"raw\">\n   ";
    return xml;
  };
  // The arrays' data go in the reverse of the order the XML names them (types first,
  // original_id last): meshio (5.0) finds each array by its offset while it rewrites the
  // offsets of the arrays it has read, and with equal-sized point arrays a rewritten
  // offset can equal a later array's; searching in document order, it then takes the
  // wrong array unless every array already read comes after the one sought. VTK and
  // ParaView go by the offsets, in any order.
  std::vector<int> order(sizes.size());
  for (std::size_t b = 0; b < order.size(); ++b) order[b] = int(order.size() - 1 - b);
  // Raw arrays have offsets known now. Compressed ones are known only once written: the
  // header is reserved at its longest (20-digit offsets) and written last, the spaces
  // it does not need before the '_' that starts the data (readers skip to the '_').
  std::vector<std::string> offsets(sizes.size());
  std::uint64_t at = 0;
  for (const int b : order) {
    offsets[std::size_t(b)] = level > 0 ? std::string(20, '9') : std::to_string(at);
    at += 8 + sizes[std::size_t(b)];
  }
  const std::string first_header = header(offsets) + "_";
  f.write(level > 0 ? std::string(first_header.size(), ' ') : first_header);
  const std::uint64_t data_start = f.offset();
  auto begin = [&](int b) {
    offsets[std::size_t(b)] = std::to_string(f.offset() - data_start);
    return VtuArray(f, sizes[std::size_t(b)], level);
  };

  auto write_ids = [&] {
    VtuArray ids_out = begin(0);
    std::vector<std::uint64_t> ids(kPointChunk);
    for (std::uint64_t first = 0; first < n; first += kPointChunk) {
      const std::size_t k = std::size_t(std::min<std::uint64_t>(kPointChunk, n - first));
      r.read_points(first, k, nullptr, ids.data());
      ids_out.put(ids.data(), 8 * k);
    }
    ids_out.finish();
  };
  auto write_point_data = [&](int k) {
    VtuArray values = begin(1 + k);
    values.put(o.point_data[std::size_t(k)].values.data(), 8 * n);
    values.finish();
  };
  // The coordinates straight from the records.
  auto write_xyz = [&] {
    VtuArray xyz_out = begin(P);
    const auto records = r.point_records();
    const std::size_t rec = r.header().point_record_bytes(), cb = f32 ? 12 : 24;
    std::vector<char> chunk(kPointChunk * cb);
    for (std::uint64_t first = 0; first < n; first += kPointChunk) {
      const std::size_t k = std::size_t(std::min<std::uint64_t>(kPointChunk, n - first));
      const std::uint8_t* src = records.data() + first * rec;
      for (std::size_t i = 0; i < k; ++i) std::memcpy(chunk.data() + i * cb, src + i * rec, cb);
      xyz_out.put(chunk.data(), k * cb);
      if (o.on_points) o.on_points(k);
    }
    xyz_out.finish();
  };
  // The tets pass; offsets and types follow from the count.
  auto write_cells = [&] {
    VtuArray cells = begin(P + 1);
    for_each_frame(r, o,
                   [&](const std::vector<std::uint64_t>& labels) { cells.put(labels.data(), 8 * labels.size()); });
    cells.finish();
  };
  auto write_ends = [&] {
    VtuArray ends = begin(P + 2);
    std::vector<std::uint64_t> chunk;
    for (std::uint64_t i = 0; i < t; i += kPointChunk) {
      chunk.clear();
      for (std::uint64_t j = i; j < std::min<std::uint64_t>(t, i + kPointChunk); ++j) chunk.push_back(4 * (j + 1));
      ends.put(chunk.data(), 8 * chunk.size());
    }
    ends.finish();
  };
  auto write_types = [&] {
    VtuArray types = begin(P + 3);
    const std::vector<std::uint8_t> tetra(kPointChunk, 10);  // VTK_TETRA
    for (std::uint64_t i = 0; i < t; i += kPointChunk)
      types.put(tetra.data(), std::size_t(std::min<std::uint64_t>(kPointChunk, t - i)));
    types.finish();
  };
  for (const int b : order) {
    if (b == 0)
      write_ids();
    else if (b < P)
      write_point_data(b - 1);
    else if (b == P)
      write_xyz();
    else if (b == P + 1)
      write_cells();
    else if (b == P + 2)
      write_ends();
    else
      write_types();
  }
  f.write("\n  </AppendedData>\n</VTKFile>\n");
  if (level > 0) {
    std::string xml = header(offsets);
    xml.append(data_start - 1 - xml.size(), ' ').push_back('_');
    f.write_at(0, xml.data(), xml.size());
  }
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

// Gmsh 4.1 binary: the section headers in text, the numbers as native (little-endian)
// size_t, int and double, each section's data followed by a newline.
template <class T>
void put(OutputFile& f, T v) {
  f.write(&v, sizeof v);
}

void write_gmsh(const TetReader& r, OutputFile& f, const MeshExportOptions& o) {
  Text out(f);
  const std::uint64_t n = r.point_count(), t = r.tet_count();
  const bool bin = o.binary;
  static_assert(sizeof(std::size_t) == 8 && sizeof(int) == 4, "Gmsh binary sizes");
  out.s(bin ? "$MeshFormat\n4.1 1 8\n" : "$MeshFormat\n4.1 0 8\n");
  if (bin) put<int>(f, 1), out.c('\n');  // the one, to tell the byte order
  out.s("$EndMeshFormat\n$Nodes\n");
  // One node block on volume entity 1: tags 1..N, then their coordinates.
  if (bin) {
    for (std::size_t v : {std::size_t(1), std::size_t(n), std::size_t(1), std::size_t(n)}) put(f, v);
    for (int v : {3, 1, 0}) put(f, v);
    put<std::size_t>(f, n);
    for (std::uint64_t i = 1; i <= n; ++i) put<std::size_t>(f, i);
    for_each_point_chunk(r, o, [&](const double* xyz, const std::uint64_t*, std::size_t k) { f.write(xyz, 24 * k); });
    out.c('\n');
  } else {
    out.s("1 ").u(n).s(" 1 ").u(n).c('\n').s("3 1 0 ").u(n).c('\n');
    for (std::uint64_t i = 1; i <= n; ++i) out.u(i).c('\n');
    for_each_point_chunk(r, o, [&](const double* xyz, const std::uint64_t*, std::size_t k) {
      for (std::size_t i = 0; i < k; ++i) out.d(xyz[3 * i]).c(' ').d(xyz[3 * i + 1]).c(' ').d(xyz[3 * i + 2]).c('\n');
    });
  }
  out.s("$EndNodes\n$Elements\n");
  std::uint64_t tag = 1;
  if (bin) {
    for (std::size_t v : {std::size_t(1), std::size_t(t), std::size_t(1), std::size_t(t)}) put(f, v);
    for (int v : {3, 1, 4}) put(f, v);
    put<std::size_t>(f, t);
    std::vector<std::uint64_t> rows;
    for_each_frame(r, o, [&](const std::vector<std::uint64_t>& l) {
      rows.resize(l.size() / 4 * 5);
      for (std::size_t i = 0, j = 0; i < l.size(); i += 4, j += 5) {
        rows[j] = tag++;
        for (int c = 0; c < 4; ++c) rows[j + 1 + c] = l[i + c] + 1;
      }
      f.write(rows.data(), 8 * rows.size());
    });
    out.c('\n');
  } else {
    out.u(1).c(' ').u(t).s(" 1 ").u(t).c('\n').s("3 1 4 ").u(t).c('\n');
    for_each_frame(r, o, [&](const std::vector<std::uint64_t>& l) {
      for (std::size_t i = 0; i < l.size(); i += 4) {
        out.u(tag++).c(' ').u(l[i] + 1).c(' ').u(l[i + 1] + 1).c(' ').u(l[i + 2] + 1).c(' ').u(l[i + 3] + 1).c('\n');
      }
    });
  }
  out.s("$EndElements\n");
  // The original ids as a one-component node view (binary node tags are ints).
  if (bin && n > std::uint64_t(INT_MAX)) return;
  out.s("$NodeData\n1\n\"original_id\"\n1\n0\n3\n0\n1\n").u(n).c('\n');
  std::uint64_t node = 1;
  struct Row {
    int tag;
    double value;
  } __attribute__((packed));
  std::vector<Row> rows;
  for (std::uint64_t first = 0; first < n; first += kPointChunk) {
    const std::size_t k = std::size_t(std::min<std::uint64_t>(kPointChunk, n - first));
    std::vector<std::uint64_t> ids(k);
    r.read_points(first, k, nullptr, ids.data());
    if (bin) {
      rows.resize(k);
      for (std::size_t i = 0; i < k; ++i) rows[i] = {int(node++), double(ids[i])};
      f.write(rows.data(), sizeof(Row) * k);
    } else {
      for (std::size_t i = 0; i < k; ++i) out.u(node++).c(' ').u(ids[i]).c('\n');
    }
  }
  if (bin) out.c('\n');
  out.s("$EndNodeData\n");
  // The point data: one view each, the same layout.
  for (const PointDataArray& a : o.point_data) {
    out.s("$NodeData\n1\n\"").s(a.name).s("\"\n1\n0\n3\n0\n1\n").u(n).c('\n');
    for (std::uint64_t first = 0; first < n; first += kPointChunk) {
      const std::size_t k = std::size_t(std::min<std::uint64_t>(kPointChunk, n - first));
      const double* v = a.values.data() + first;
      if (bin) {
        rows.resize(k);
        for (std::size_t i = 0; i < k; ++i) rows[i] = {int(first + i + 1), v[i]};
        f.write(rows.data(), sizeof(Row) * k);
      } else {
        for (std::size_t i = 0; i < k; ++i) out.u(first + i + 1).c(' ').d(v[i]).c('\n');
      }
    }
    if (bin) out.c('\n');
    out.s("$EndNodeData\n");
  }
}

void write_tetgen_node(const TetReader& r, OutputFile& f, const MeshExportOptions& o) {
  Text out(f);
  out.u(r.point_count()).s(" 3 1 0\n");  // one attribute: the original id
  std::uint64_t index = 1;
  for_each_point_chunk(r, o, [&](const double* xyz, const std::uint64_t* ids, std::size_t k) {
    for (std::size_t i = 0; i < k; ++i) {
      out.u(index++).c(' ').d(xyz[3 * i]).c(' ').d(xyz[3 * i + 1]).c(' ').d(xyz[3 * i + 2]).c(' ').u(ids[i]).c('\n');
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
  if (ends_with(path, ".vtk")) return MeshFormat::kVtk;
  if (ends_with(path, ".mesh")) return MeshFormat::kMedit;
  if (ends_with(path, ".msh")) return MeshFormat::kGmsh;
  if (ends_with(path, ".node") || ends_with(path, ".ele")) return MeshFormat::kTetgen;
  if (ends_with(path, ".xdmf")) return MeshFormat::kXdmf;
  throw UsageError(path + ": unknown mesh format (use .vtu, .vtk, .mesh, .msh, .node or .xdmf)");
}

const char* mesh_format_name(MeshFormat format) {
  switch (format) {
    case MeshFormat::kVtu:
      return "VTK XML unstructured grid (.vtu)";
    case MeshFormat::kVtk:
      return "legacy VTK unstructured grid (.vtk)";
    case MeshFormat::kMedit:
      return "Medit (.mesh)";
    case MeshFormat::kGmsh:
      return "Gmsh 4.1 (.msh)";
    case MeshFormat::kTetgen:
      return "TetGen (.node + .ele)";
    case MeshFormat::kXdmf:
      return "XDMF 3 + HDF5 (.xdmf + .h5)";
  }
  return "?";
}

MeshExportResult export_mesh(const TetReader& reader, const std::string& path, MeshFormat format,
                             const MeshExportOptions& options) {
  if (options.binary && format != MeshFormat::kGmsh && format != MeshFormat::kVtk) {
    throw UsageError("--binary is for .msh and .vtk (" + std::string(mesh_format_name(format)) + " has one encoding)");
  }
  if (options.compress_level != 0 && format != MeshFormat::kVtu) {
    throw UsageError("--compress is for .vtu (" + std::string(mesh_format_name(format)) + " is not compressed)");
  }
  if (options.compress_level < 0 || options.compress_level > 9) {
    throw UsageError("--compress level " + std::to_string(options.compress_level) + ": use 1 to 9");
  }
  if (!options.point_data.empty() && (format == MeshFormat::kMedit || format == MeshFormat::kTetgen)) {
    throw UsageError(path + ": " + mesh_format_name(format) +
                     " has no place for point data (use .vtu, .vtk, .msh or .xdmf)");
  }
  for (std::size_t k = 0; k < options.point_data.size(); ++k) {
    const PointDataArray& a = options.point_data[k];
    const bool plain = !a.name.empty() && std::all_of(a.name.begin(), a.name.end(), [](char c) {
      return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.';
    });
    // The formats quote names differently (XML attributes, legacy VTK's blank-separated
    // words, Gmsh strings): only names every one of them takes as they are.
    if (!plain) throw UsageError("point data name '" + a.name + "': use letters, digits, '_', '-' and '.' only");
    if (a.name == "original_id") throw UsageError("point data name 'original_id' is taken by the input index");
    for (std::size_t j = 0; j < k; ++j)
      if (options.point_data[j].name == a.name) throw UsageError("point data name '" + a.name + "' is given twice");
    if (a.values.size() != reader.point_count()) {
      throw UsageError("point data '" + a.name + "' has " + std::to_string(a.values.size()) +
                       " values, the container has " + std::to_string(reader.point_count()) + " points");
    }
  }
  if (format == MeshFormat::kXdmf && !hdf5_available()) {
    throw UsageError(path +
                     ": .xdmf needs HDF5 for its heavy data, and this tetstream was built without it "
                     "(install libhdf5-dev and rebuild, or convert to .vtu)");
  }
  reader.verify_points();
  MeshExportResult result;
  auto finish = [&result](OutputFile& f) {
    result.bytes += f.offset();
    f.commit();
    result.files.push_back(f.path());
  };
  if (format == MeshFormat::kXdmf) {
    write_xdmf(reader, path, options, result);
    return result;
  }
  if (format == MeshFormat::kTetgen) {
    const std::string base = path.substr(0, path.rfind('.'));
    // BASE.ele is a name the user did not give (see OutputClaim::Kind::kBeside).
    const OutputClaim ele_claim(base + ".ele", OutputClaim::Kind::kBeside, base + ".node");
    OutputFile node(base + ".node"), ele(base + ".ele", std::size_t(8) << 20, &ele_claim);
    write_tetgen_node(reader, node, options);
    write_tetgen_ele(reader, ele, options);
    finish(node);
    finish(ele);
    return result;
  }
  OutputFile f(path);
  switch (format) {
    case MeshFormat::kVtu:
      write_vtu(reader, f, options);
      break;
    case MeshFormat::kVtk:
      write_vtk(reader, f, options);
      break;
    case MeshFormat::kMedit:
      write_medit(reader, f, options);
      break;
    case MeshFormat::kGmsh:
      write_gmsh(reader, f, options);
      break;
    case MeshFormat::kTetgen:
    case MeshFormat::kXdmf:
      break;
  }
  finish(f);
  return result;
}

}  // namespace tetstream::io
