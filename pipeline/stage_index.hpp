#pragma once
// The index stage of `run`: the sorted file mapped, its spatial index (pipeline/point_index.hpp),
// and the global convex hull's boundary points with their own small index: the
// SortedView that the triangulation reads.
//
// No checkpoint record: everything here is rebuilt from the sorted file in about one
// pass, which costs less than writing it and checking it again on a resume.
#include "pipeline/point_index.hpp"
#include "pipeline/point_sort.hpp"
#include "pipeline/segment.hpp"

#include <boost/iostreams/device/mapped_file.hpp>

#include <cstddef>
#include <cstdint>

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

  SortedView& view() { return view_; }
  const SortedView& view() const { return view_; }
  const PointIndex& index() const { return index_; }
  // The whole mapping, whose pages the triangulation hands back between zones.
  const char* mapped_data() const { return mapping_.data(); }
  std::size_t mapped_bytes() const { return mapping_.size(); }
  const std::string& path() const { return sorted_.path; }

 private:
  const SortedPoints& sorted_;
  const int threads_;
  // Declared before the view and the indexes, which point into it.
  boost::iostreams::mapped_file_source mapping_;
  SortedView view_;
  PointIndex index_, hull_index_;
};

}  // namespace tetstream::pipeline
