#pragma once
// The index stage of `run`: the sorted file mapped, its spatial index (pipeline/point_index.hpp),
// and the global convex hull's boundary points with their own small index: the
// SortedView that the triangulation reads.
//
// No checkpoint record: everything here is rebuilt from the sorted file in about one
// pass, which costs less than writing it and checking it again on a resume.
#include "pipeline/window/point_index.hpp"
#include "pipeline/sort/point_sort.hpp"
#include "pipeline/window/zone_triangulator.hpp"
#include "pipeline/util/stage_time.hpp"

#include <boost/iostreams/device/mapped_file.hpp>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace tetstream::pipeline {

class IndexStage {
 public:
  // The indexes take what this input needs (a few bytes a point, measured once built
  // and recorded in the ledger by the triangulation's plan); they are built on
  // `threads` threads.
  IndexStage(const SortedPoints& sorted, int threads) : sorted_(sorted), threads_(threads) {}
  IndexStage(const IndexStage&) = delete;  // the view points into the indexes
  IndexStage& operator=(const IndexStage&) = delete;

  // Maps the sorted file (IoError when it cannot) and sets up the view over it.
  void prepare();
  // The key samples, the index over every point, the hull's boundary points (the
  // hull of the sort's candidates, by increasing label) and their index. Every page
  // of the sorted file that this reads is handed back behind it.
  void run();
  // The same, with the point index in a file of the job's work directory (`path`)
  // instead of memory: built a chunk of blocks at a time and written there, then
  // mapped, its pages counted in 2 MiB regions within `resident_bytes`
  // (MappedRegions) and handed back least recently read first, and all of them after
  // each zone (release_pages). For inputs whose index would crowd the windows out of
  // the budget (about 7.5 bytes a point resident: 7.5 GB at 10^9 points); the queries
  // read the blocks near their window, so the file's share stays small.
  void run_on_disk(const std::string& path, std::uint64_t resident_bytes);

  // ---- the ranks of a job build one index together (pipeline/run_distributed.cpp),
  // shared through a file in the job's work directory: each rank builds a K-th of the
  // blocks, and every rank maps the whole file (PointIndex::attach), which the page
  // cache holds once a node rather than once a rank. Every rank calls the steps in
  // order, after prepare(); the collective calls between them are the caller's.
  // 1: the key samples and this rank's blocks; returns its node count.
  std::uint64_t build_shared_part(int rank, int ranks);
  // 2 (rank 0 alone, before any rank writes): the file, sized for every rank's nodes.
  void create_shared_file(const std::string& path, std::uint64_t total_nodes) const;
  // 3: this rank's part into the file (its nodes numbered after the ranks' before it), synced.
  void write_shared_part(const std::string& path, std::uint64_t total_nodes, std::uint64_t first_node);
  // 4: the whole index mapped from the file (planned as a K-th of it), then the hull.
  void attach_shared(const std::string& path, std::uint64_t total_nodes, int ranks);

  // Hands back the mappings' pages (the sorted points', the shared index's): the
  // triangulation calls it after each segment, so what stays resident is what the
  // next segment reads.
  void release_pages() const;

  SortedView& view() { return view_; }
  const SortedView& view() const { return view_; }
  const PointIndex& index() const { return index_; }
  // The whole mapping, whose pages the triangulation hands back between zones.
  const char* mapped_data() const { return mapping_.data(); }
  std::size_t mapped_bytes() const { return mapping_.size(); }
  const std::string& path() const { return sorted_.path; }
  // run()'s phases, timed: "index.keys" (the key samples), "index.build" (the point
  // index), "index.hull" (the global hull and its index), for the summary's stages.
  const std::vector<std::pair<std::string, StageTime>>& phases() const { return phases_; }

 private:
  std::uint32_t block_points(std::uint64_t count) const;  // the index blocks' labels for `count` points
  template <class BuildPointIndex>
  void run_phases(BuildPointIndex&& build_point_index);  // run()'s phases around the point index's build
  void build_on_disk(const std::string& path, std::uint64_t resident_bytes);  // run_on_disk's point index
  void find_hull();  // the hull's boundary points (of the sort's candidates) and their index

  const SortedPoints& sorted_;
  const int threads_;
  // Declared before the view and the indexes, which point into it.
  boost::iostreams::mapped_file_source mapping_;
  boost::iostreams::mapped_file_source index_mapping_;  // the shared index's file (attach_shared, run_on_disk)
  std::unique_ptr<MappedRegions> index_regions_;        // its resident pages (run_on_disk)
  SortedView view_;
  PointIndex index_, hull_index_;
  std::vector<std::pair<std::string, StageTime>> phases_;
};

}  // namespace tetstream::pipeline
