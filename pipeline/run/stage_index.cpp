#include "pipeline/run/stage_index.hpp"

#include "core/error.hpp"
#include "io/output_file.hpp"
#include "pipeline/sort/hull.hpp"
#include "pipeline/run/stage.hpp"
#include "pipeline/files/temp_files.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <exception>
#include <fcntl.h>
#include <unistd.h>
#include <vector>

namespace tetstream::pipeline {

namespace {
// The index file, opened without following a link (it is in the job's own work
// directory, which the job, or rank 0, holds locked).
int open_shared(const std::string& path, int flags) {
  const int fd = ::open(path.c_str(), flags | O_NOFOLLOW | O_CLOEXEC, 0600);
  if (fd < 0) throw IoError(path + ": cannot open the point index's file: " + std::strerror(errno));
  return fd;
}
}  // namespace

void IndexStage::prepare() {
  try {
    // From the file's start to the records' end: a points section inside the partial
    // output is mapped with the header before it (a few hundred bytes), so that the
    // mapping's offsets are the file's (MappedRegions reads by them), and without
    // the frames the writer appends after it.
    mapping_.open(sorted_.path, std::size_t(sorted_.offset + sorted_.count * sorted_.layout.bytes()));
  } catch (const std::exception& e) {
    throw IoError(sorted_.path + ": cannot map: " + e.what());
  }
  view_.points = PointRecords(mapping_.data() + sorted_.offset, sorted_.layout);
  view_.count = sorted_.count;
  view_.axis = sorted_.axis;
  for (int k = 0; k < 3; ++k) view_.bbox_min[k] = sorted_.bbox_min[k], view_.bbox_max[k] = sorted_.bbox_max[k];
}

std::uint32_t IndexStage::block_points(std::uint64_t count) const {
  double volume = 1;
  for (int k = 0; k < 3; ++k) volume *= view_.bbox_max[k] - view_.bbox_min[k];
  return PointIndex::block_points_for(count, view_.bbox_max[view_.axis] - view_.bbox_min[view_.axis], volume);
}

// The stage's phases around the point index's build, timed for the summary.
template <class BuildPointIndex>
void IndexStage::run_phases(BuildPointIndex&& build_point_index) {
  const ScopedThreads threads(threads_);
  StageMeter meter;
  auto phase_done = [&](const char* name) {
    phases_.emplace_back(name, meter.elapsed());
    meter.restart();
  };
  view_.sample_keys(/*release_file_pages=*/true);
  phase_done("index.keys");
  build_point_index();
  view_.index = &index_;
  phase_done("index.build");
  find_hull();
  phase_done("index.hull");
}

void IndexStage::run() {
  run_phases([&] { index_.build(view_.points, view_.count, view_.axis, block_points(view_.count), true); });
}

void IndexStage::run_on_disk(const std::string& path, std::uint64_t resident_bytes) {
  run_phases([&] { build_on_disk(path, resident_bytes); });
}

void IndexStage::build_on_disk(const std::string& path, std::uint64_t resident_bytes) {
  const SortedView& view = view_;
  const std::uint32_t points_a_block = block_points(view.count);
  const std::uint64_t blocks = PointIndex::blocks_for(view.count, points_a_block);
  const std::uint64_t total_nodes = PointIndex::node_count_for(view.count, points_a_block);
  create_shared_file(path, total_nodes);
  // A chunk of blocks at a time, each built on every thread as build() does, within
  // the share: a block is 6 bytes a point and a 36-byte node for every ~24 points.
  const std::uint64_t block_bytes = std::uint64_t(points_a_block) * 8;
  const std::uint64_t chunk = std::max<std::uint64_t>(std::uint64_t(std::max(threads_, 1)) * 2,
                                                      resident_bytes / std::max<std::uint64_t>(block_bytes, 1));
  const int fd = open_shared(path, O_RDWR);
  try {
    std::uint64_t first_node = 0;
    for (std::uint64_t b = 0; b < blocks; b += chunk) {
      index_.build_part(view.points, view.count, view.axis, points_a_block, b, std::min(blocks, b + chunk),
                        /*release_file_pages=*/true);
      const std::uint64_t nodes = index_.part_nodes();
      index_.write_part(fd, path, total_nodes, first_node);
      first_node += nodes;
    }
    if (first_node != total_nodes) throw std::logic_error("run_on_disk: the blocks' nodes do not add up");
  } catch (...) {
    ::close(fd);
    throw;
  }
  ::close(fd);
  const PointIndex::FileLayout layout = PointIndex::file_layout(view.count, total_nodes, blocks);
  try {
    index_mapping_.open(path, std::size_t(layout.bytes));
  } catch (const std::exception& e) {
    throw IoError(path + ": cannot map: " + e.what());
  }
  const std::uint64_t share = std::min<std::uint64_t>(resident_bytes, layout.bytes);
  index_regions_ =
      std::make_unique<MappedRegions>(index_mapping_.data(), index_mapping_.size(),
                                      std::max<std::size_t>(1, std::size_t(share / MappedRegions::kRegionBytes)));
  index_.attach(reinterpret_cast<const std::byte*>(index_mapping_.data()), view.points, view.count, view.axis,
                points_a_block, total_nodes, share);
  index_.track_regions(index_regions_.get());
}

std::uint64_t IndexStage::build_shared_part(int rank, int ranks) {
  const ScopedThreads threads(threads_);
  view_.sample_keys(/*release_file_pages=*/true);
  const std::uint64_t blocks = PointIndex::blocks_for(view_.count, block_points(view_.count));
  const std::uint64_t k = std::uint64_t(std::max(ranks, 1)), r = std::uint64_t(rank);
  index_.build_part(view_.points, view_.count, view_.axis, block_points(view_.count), blocks * r / k,
                    blocks * (r + 1) / k, /*release_file_pages=*/true);
  return index_.part_nodes();
}

void IndexStage::create_shared_file(const std::string& path, std::uint64_t total_nodes) const {
  // A stopped job's file is rebuilt, never trusted (nothing records it).
  const int fd = io::create_work_file(path, O_RDWR);
  const PointIndex::FileLayout layout =
      PointIndex::file_layout(view_.count, total_nodes, PointIndex::blocks_for(view_.count, block_points(view_.count)));
  const int rc = ::ftruncate(fd, off_t(layout.bytes));
  const int saved = errno;
  ::close(fd);
  if (rc != 0) throw IoError(path + ": cannot size the shared point index: " + std::strerror(saved));
}

void IndexStage::write_shared_part(const std::string& path, std::uint64_t total_nodes, std::uint64_t first_node) {
  const int fd = open_shared(path, O_RDWR);
  try {
    index_.write_part(fd, path, total_nodes, first_node);
    if (::fdatasync(fd) != 0) throw IoError(path + ": fdatasync failed: " + std::strerror(errno));
  } catch (...) {
    ::close(fd);
    throw;
  }
  ::close(fd);
}

void IndexStage::attach_shared(const std::string& path, std::uint64_t total_nodes, int ranks) {
  const ScopedThreads threads(threads_);
  const PointIndex::FileLayout layout =
      PointIndex::file_layout(view_.count, total_nodes, PointIndex::blocks_for(view_.count, block_points(view_.count)));
  try {
    index_mapping_.open(path, std::size_t(layout.bytes));
  } catch (const std::exception& e) {
    throw IoError(path + ": cannot map: " + e.what());
  }
  if (index_mapping_.size() != layout.bytes) throw IoError(path + ": the shared point index has the wrong size");
  // Planned as a rank's share: its queries read mostly its own labels' blocks, and
  // the triangulation hands the mapping's pages back after every segment (release_pages).
  index_.attach(reinterpret_cast<const std::byte*>(index_mapping_.data()), view_.points, view_.count, view_.axis,
                block_points(view_.count), total_nodes, layout.bytes / std::uint64_t(std::max(ranks, 1)));
  view_.index = &index_;
  find_hull();
}

void IndexStage::release_pages() const {
  release_mapped_pages(mapping_.data(), mapping_.size());
  if (index_regions_) index_regions_->release_all();
  if (index_mapping_.is_open()) release_mapped_pages(index_mapping_.data(), index_mapping_.size());
}

void IndexStage::find_hull() {
  SortedView& view = view_;
  // The global hull: the hull of the runs' candidates.
  {
    std::vector<double> xyz;
    // In label order, handing the pages back behind: a shell's hull candidates are
    // all over the file.
    ReleaseBehind release(view.points, 0, true);
    for (std::uint64_t label : sorted_.hull_labels) {
      double p[3];
      view.points.xyz(label, p);
      xyz.insert(xyz.end(), p, p + 3);
      release.reached(label);
    }
    std::vector<std::uint32_t> hull = hull_vertex_candidates(xyz.data(), sorted_.hull_labels.size());
    std::sort(hull.begin(), hull.end());  // candidates are sorted by label: so are these
    for (std::uint32_t i : hull) {
      SortedPoint p;
      std::copy_n(&xyz[3 * std::size_t(i)], 3, p.xyz);
      p.original = sorted_.hull_labels[i];
      view.hull_points.push_back(p);
    }
    release_mapped_pages(mapping_.data(), mapping_.size());
  }
  {
    std::vector<double> xyz(3 * view.hull_points.size());
    std::vector<std::uint64_t> labels(view.hull_points.size());
    for (std::size_t i = 0; i < view.hull_points.size(); ++i) {
      std::copy_n(view.hull_points[i].xyz, 3, &xyz[3 * i]);
      labels[i] = view.hull_points[i].original;
    }
    view.hull_facets = hull_facet_labels(xyz.data(), labels.data(), labels.size());
  }
  if (!view.hull_points.empty())
    hull_index_.build(records_of(view.hull_points.data()), view.hull_points.size(), view.axis,
                      block_points(view.hull_points.size()), false);
  view.hull_index = &hull_index_;
}

}  // namespace tetstream::pipeline
