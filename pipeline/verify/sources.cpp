// Where verify reads from: points and tets held in memory, or a container.
#include "pipeline/verify/verify.hpp"

#include "core/error.hpp"
#include "io/tet_reader.hpp"

#include <algorithm>
#include <bit>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace tetstream::pipeline {

// ---------------------------------------------------------------------------------
// Sources.

MemorySource::MemorySource(std::vector<double> xyz, std::vector<std::uint64_t> tets, std::size_t batch_tets)
    : xyz_(std::move(xyz)), tets_(std::move(tets)) {
  if (batch_tets == 0) batch_tets = 1;
  const std::uint64_t t = tets_.size() / 4;
  for (std::uint64_t first = 0; first < t; first += batch_tets) {
    Batch b;
    b.first_tet = first;
    b.tet_count = std::min<std::uint64_t>(batch_tets, t - first);
    b.min_label = std::numeric_limits<std::uint64_t>::max();
    b.max_label = 0;
    for (std::uint64_t i = 4 * first; i < 4 * (first + b.tet_count); ++i) {
      b.min_label = std::min(b.min_label, tets_[i]);
      b.max_label = std::max(b.max_label, tets_[i]);
    }
    batches_.push_back(b);
  }
}

VerifySource::PointRecords MemorySource::points() const {
  return {reinterpret_cast<const std::uint8_t*>(xyz_.data()), 3 * sizeof(double), false};
}

void MemorySource::read_batch(std::size_t k, std::vector<std::uint32_t>& labels) const {
  const Batch& b = batches_[k];
  labels.resize(4 * b.tet_count);
  for (std::size_t i = 0; i < labels.size(); ++i) {
    const std::uint64_t l = tets_[4 * b.first_tet + i];
    if (l > 0xFFFFFFFFu) throw InputError("memory: label " + std::to_string(l) + " does not fit 32 bits");
    labels[i] = std::uint32_t(l);
  }
}

void MemorySource::read_batch(std::size_t k, std::vector<std::uint64_t>& labels) const {
  const Batch& b = batches_[k];
  labels.assign(tets_.begin() + std::ptrdiff_t(4 * b.first_tet),
                tets_.begin() + std::ptrdiff_t(4 * (b.first_tet + b.tet_count)));
}

ContainerSource::ContainerSource(const io::TetReader& reader) : reader_(reader) {}
std::uint64_t ContainerSource::point_count() const { return reader_.point_count(); }
std::uint64_t ContainerSource::tet_count() const { return reader_.tet_count(); }
std::size_t ContainerSource::batch_count() const { return std::size_t(reader_.frame_count()); }
VerifySource::Batch ContainerSource::batch(std::size_t k) const {
  const io::FrameEntry& f = reader_.frames()[k];
  return Batch{f.first_tet, f.tet_count, f.base_label, f.max_label};
}
// The reader maps the whole file; the points are read in place and frames are read
// once (the replay of the distributed check reads a frame again, from the file), so
// pages leave this process's resident set once used: a read-only file mapping's pages
// count in the peak RSS that --memory bounds (23.2 GiB at --memory 16G on a 40 GiB
// container before the frames were released too).
VerifySource::PointRecords ContainerSource::points() const {
  // format.md §3.4: little-endian coordinates, then the original index.
  static_assert(std::endian::native == std::endian::little, "verify reads the container's points in place");
  const io::TetFileHeader& h = reader_.header();
  return {reader_.point_records().data(), h.point_record_bytes(), h.coord_type == io::CoordType::kFloat32};
}
int ContainerSource::sort_axis() const { return io::perturbation_axis(reader_); }
void ContainerSource::release_points(std::uint64_t first, std::uint64_t n) const {
  reader_.release_point_pages(first, n);
}
void ContainerSource::read_batch(std::size_t k, std::vector<std::uint32_t>& labels) const {
  reader_.read_frame(k, labels);
  reader_.release_frame_pages(k);
}
void ContainerSource::read_batch(std::size_t k, std::vector<std::uint64_t>& labels) const {
  reader_.read_frame(k, labels);
  reader_.release_frame_pages(k);
}
std::string ContainerSource::name() const { return reader_.path(); }
std::string ContainerSource::directory() const {
  const std::filesystem::path p = std::filesystem::path(reader_.path()).parent_path();
  return p.empty() ? std::string(".") : p.string();
}

}  // namespace tetstream::pipeline
