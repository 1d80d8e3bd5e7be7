#pragma once
// Internals of the HDF5 code (point_hdf5.cpp reads points, mesh_export_xdmf.cpp writes
// a mesh's heavy data): error-stack silencing and an owning handle. Included only by
// files built with HDF5.
#include <hdf5.h>

namespace tetstream::io::hdf5 {

// HDF5 prints its error stack to stderr unless told not to; our errors are one line.
inline void quiet() { H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr); }

class Handle {
 public:
  Handle(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
  ~Handle() {
    if (id_ >= 0) close_(id_);
  }
  Handle(Handle&& o) noexcept : id_(o.id_), close_(o.close_) { o.id_ = -1; }
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;
  hid_t get() const { return id_; }
  bool ok() const { return id_ >= 0; }
  // Closes now and says whether that worked (a file's close flushes it).
  bool close() {
    const hid_t id = id_;
    id_ = -1;
    return id < 0 || close_(id) >= 0;
  }

 private:
  hid_t id_;
  herr_t (*close_)(hid_t);
};

}  // namespace tetstream::io::hdf5
