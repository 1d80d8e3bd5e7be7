#pragma once
// Converters from a .tets container to the mesh formats downstream tools read:
//
//   .vtu   VTK XML UnstructuredGrid, binary appended raw data, header_type UInt64,
//          Int64 connectivity and offsets, point data "original_id" (Int64)
//   .mesh  Medit (MeshVersionFormatted 2, ASCII, 1-based)
//   .msh   Gmsh 4.1 ASCII: one node block, one block of 4-node tetrahedra (type 4)
//   .node  TetGen .node + .ele (ASCII, 1-based) beside it
//
// Vertex i of the mesh is the point of label i (the container's sorted order); every
// tet keeps its positive orientation (det[b-a, c-a, d-a] > 0), which is what all four
// formats expect. Coordinates are written exactly: float64 values in text as the
// shortest decimal that reads back to the same double (float32 values as the double
// they equal).
//
// Streaming in bounded memory: one pass over the points, then one over the frames (the
// counts the .vtu header needs are in the container's header and footer), whatever the
// size of the output. Each file goes to NAME.partial and is renamed when complete.
#include "io/tet_reader.hpp"

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace tetstream::io {

enum class MeshFormat { kVtu, kMedit, kGmsh, kTetgen };

// From the extension (.vtu, .mesh, .msh, .node or .ele); throws UsageError otherwise.
MeshFormat mesh_format_for(const std::string& path);
const char* mesh_format_name(MeshFormat format);

struct MeshExportOptions {
  // Progress: called with the number of points / tets just written.
  std::function<void(std::uint64_t)> on_points, on_tets;
};

struct MeshExportResult {
  std::vector<std::string> files;  // written, in order
  std::uint64_t bytes = 0;
};

// Writes the mesh; checks the points' checksum first. Throws InputError for a damaged
// container, IoError when writing fails (no partial output is left behind).
MeshExportResult export_mesh(const TetReader& reader, const std::string& path, MeshFormat format,
                             const MeshExportOptions& options = {});

}  // namespace tetstream::io
