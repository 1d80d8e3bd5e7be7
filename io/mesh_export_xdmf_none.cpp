// .xdmf in a build without HDF5: export_mesh refuses it before this is reached.
#include "core/error.hpp"
#include "io/mesh_export_detail.hpp"

namespace tetstream::io::mesh_detail {

void write_xdmf(const TetReader&, const std::string& path, const MeshExportOptions&, MeshExportResult&) {
  throw UsageError(path + ": this tetstream was built without HDF5, which .xdmf needs for its heavy data");
}

}  // namespace tetstream::io::mesh_detail
