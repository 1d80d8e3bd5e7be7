#pragma once
// Converters from a .tets container to the mesh formats downstream tools read:
//
//   .vtu   VTK XML UnstructuredGrid, appended data, header_type UInt64, Int64
//          connectivity and offsets, point data "original_id" (Int64); raw, or zlib
//          compressed (compressor="vtkZLibDataCompressor") with `compress_level` > 0
//   .vtk   legacy VTK (DataFile Version 5.1) UNSTRUCTURED_GRID, ASCII or BINARY
//          (big-endian, `binary`): POINTS double, OFFSETS/CONNECTIVITY vtktypeint64,
//          CELL_TYPES 10, point data SCALARS original_id vtktypeint64
//   .mesh  Medit (MeshVersionFormatted 2, ASCII, 1-based)
//   .msh   Gmsh 4.1, ASCII or binary (`binary`): one node block, one block of 4-node
//          tetrahedra (type 4), and $NodeData "original_id" (in binary only while the
//          point count fits the format's int node tags)
//   .node  TetGen .node + .ele (ASCII, 1-based) beside it; the .node's one point
//          attribute is the original id
//   .xdmf  XDMF 3 with its heavy data in BASE.h5 beside it (HDF5: /points N x 3 float64,
//          /tets T x 4 uint64, /original_id N int64); only in a build with HDF5
//
// Vertex i of the mesh is the point of label i (the container's sorted order); every
// tet keeps its positive orientation (det[b-a, c-a, d-a] > 0), which is what all the
// formats expect. "original_id" is the point's index in the input of `run`. A .vtu's
// appended data holds its arrays in the reverse of the order its XML names them
// (meshio 5.0 misreads same-sized arrays otherwise: mesh_export.cpp says why).
// Coordinates are written exactly: float64 values in text as the shortest decimal that
// reads back to the same double (float32 values as the double they equal).
//
// Point data arrays (MeshExportOptions::point_data) follow "original_id" under their
// names: .vtu Float64 DataArrays in PointData, .vtk SCALARS NAME double, .msh one
// $NodeData view each, .xdmf /NAME N float64 and an Attribute.
//
// Streaming in bounded memory (besides the point data arrays given): one pass over the points, then one over the frames
// (the counts the headers need are in the container's header and footer), whatever the size of the output. Each file
// goes to NAME.partial and is renamed when complete.
#include "io/tet_reader.hpp"

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace tetstream::io {

enum class MeshFormat { kVtu, kMedit, kGmsh, kTetgen, kVtk, kXdmf };

// From the extension (.vtu, .vtk, .mesh, .msh, .node or .ele, .xdmf); throws
// UsageError otherwise.
MeshFormat mesh_format_for(const std::string& path);
const char* mesh_format_name(MeshFormat format);

// A per-point array written as point data beside "original_id" (`convert --point-data`,
// `--las-attributes`): values[i] belongs to vertex i (label i, the container's order).
// Written as float64 in every format (integers up to 2^53 are exact in it).
struct PointDataArray {
  std::string name;  // letters, digits, '_', '-', '.'; not "original_id"
  std::vector<double> values;
};

struct MeshExportOptions {
  // .msh and .vtk: binary instead of ASCII.
  bool binary = false;
  // .vtu: 0 writes raw appended data, 1..9 zlib-compresses it at that level.
  int compress_level = 0;
  // Progress: called with the number of points / tets just written.
  std::function<void(std::uint64_t)> on_points, on_tets;
  // Point data: .vtu, .vtk, .msh and .xdmf have a place for it; a UsageError for the
  // others, a name used twice, or an array whose length is not the point count.
  std::vector<PointDataArray> point_data;
};

struct MeshExportResult {
  std::vector<std::string> files;  // written, in order
  std::uint64_t bytes = 0;
};

// Writes the mesh; checks the points' checksum first. Throws InputError for a damaged
// container, UsageError for an option the format does not take (or .xdmf without HDF5),
// IoError when writing fails (no partial output is left behind).
MeshExportResult export_mesh(const TetReader& reader, const std::string& path, MeshFormat format,
                             const MeshExportOptions& options = {});

}  // namespace tetstream::io
