#pragma once
// `convert --las-attributes`: the attributes a LiDAR user colours by, read again from the
// LAS file a container was made from and put in the container's point order, as point
// data for the mesh writers (io/mesh_export.hpp).
//
// A container keeps each point's original id (its index in the input as `run` read it,
// after the LAS filters); the LAS file is read through the same filters, so its k-th
// point kept is original id k. The file must still be the one the container was made
// from: every container point's coordinates are compared with the file's, and the
// number of points kept with the container's input count, so a file replaced, edited
// or truncated since is refused, not silently mismatched.
#include "io/mesh_export.hpp"
#include "io/point_reader.hpp"
#include "io/tet_reader.hpp"

#include <string>
#include <vector>

namespace tetstream::io {

// "intensity", "classification", "return_number" and, when the point format has it,
// "gps_time", for each point of `reader` (label order). `read` carries the filters the
// container was made with. Throws InputError (the file gone, not LAS, or changed).
std::vector<PointDataArray> las_point_data(const TetReader& reader, const std::string& las_path,
                                           const PointReadOptions& read);

}  // namespace tetstream::io
