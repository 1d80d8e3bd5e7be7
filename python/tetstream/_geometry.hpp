#pragma once
// The scipy.spatial.Delaunay queries of tetstream._core (_geometry.cpp).
#include <pybind11/pybind11.h>

namespace tetstream::python {
void register_geometry(pybind11::module_& m);
}  // namespace tetstream::python
