#pragma once
// `tetstream convert` of a periodic container (docs/periodic.md, "Convert"): the tets
// unwrapped, each drawn where its smallest label's point stands, its other vertices at
// their images x + o L where the offsets say so; the images are extra points of the
// mesh, marked by the point field "image" (1; 0 for the box's own points), and
// "periodic_label" names the point each one is an image of. Written as a plain container
// in `dir` (a work file), which any mesh exporter then converts.
#include "io/mesh_export.hpp"

#include <string>
#include <vector>

namespace tetstream::pipeline::periodic {

struct Unwrapped {
  std::string container;  // the plain container in dir
  std::vector<io::PointDataArray> point_data;
  std::uint64_t images = 0;
};

Unwrapped unwrap_periodic(const std::string& container, const std::string& dir);

}  // namespace tetstream::pipeline::periodic
