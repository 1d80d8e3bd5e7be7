// HDF5 input in a build without libhdf5 (TETSTREAM_HDF5 off or not found): every entry
// point says so, as a usage error (exit 2).
#include "io/point_detail.hpp"

namespace tetstream::io {
namespace {
[[noreturn]] void unavailable(const std::string& path) {
  throw UsageError(
      path + ": this tetstream was built without HDF5 (install libhdf5-dev and rebuild with -DTETSTREAM_HDF5=ON)");
}
}  // namespace

bool hdf5_available() { return false; }

std::vector<Hdf5PointDataset> list_hdf5_point_datasets(const std::string& path) { unavailable(path); }
std::array<double, 3> hdf5_box_size(const std::string& path) { unavailable(path); }

namespace detail {
std::unique_ptr<PointReader> open_hdf5(const std::string& path, const PointReadOptions&, bool) { unavailable(path); }
}  // namespace detail

}  // namespace tetstream::io
