#pragma once
// Stage 1 of `run`: the external sort of the input points along the longest axis of
// their bounding box, within a memory budget.
//
//   pass 1  read the input once for its bounding box and count (stdin is spooled to
//           a raw file in tmpdir so that it can be read twice);
//   pass 2  read it again into runs of at most `run_points` records, sort each run
//           by (axis coordinate, the other two coordinates, original index), write it
//           to tmpdir; on the way keep each run's convex-hull vertex candidates;
//   merge   k-way merge of the runs into one sorted file, dropping exact duplicates
//           (they are adjacent in this order; the first in input order is kept).
//
// A point's label is its position in the sorted, duplicate-free file. The order is a
// total order on distinct points, so the labels do not depend on the budget.
#include "io/point_reader.hpp"
#include "pipeline/sort/point_record.hpp"
#include "pipeline/files/temp_files.hpp"
#include "pipeline/util/stage_time.hpp"

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace tetstream::pipeline {

class MemoryBudget;

// One record of the sorted file: coordinates and the index of the point in the input.
struct SortedPoint {
  double xyz[3];
  std::uint64_t original;
};
static_assert(sizeof(SortedPoint) == 32);
// Points in memory as records: SortedPoint has the bytes of PointRecord<double, uint64>.
inline PointRecords records_of(const SortedPoint* points) { return PointRecords(points, RecordLayout{false, true}); }

// One finished run of pass 2 and its hull vertex candidates (original indices).
struct SortRunFile {
  std::string path;
  std::uint64_t records = 0;
  std::string hull_path;  // hull_count uint64 original indices
  std::uint64_t hull_count = 0;
  std::uint32_t crc32c = 0, hull_crc32c = 0;  // of the two files' bytes (a resume checks them)
};

// How far the sort of a resumable job got: the caller persists it (pipeline/checkpoint)
// after each step and hands it back to a resumed sort, which skips those steps.
struct SortProgress {
  bool scanned = false;  // pass 1 done: the fields below are set
  std::uint64_t input_count = 0;
  double bbox_min[3] = {0, 0, 0}, bbox_max[3] = {0, 0, 0};
  int axis = 0;
  bool float32 = false;           // every coordinate of the input is a float32 (PointReader::float32_input)
  std::vector<SortRunFile> runs;  // pass 2's finished runs, in order, in compact records
  // Files of runs the merge started to consume (it gives their space back as it
  // reads: no longer runs to adopt); removed once the sort is committed.
  std::vector<std::string> consumed;
};

struct SortedPoints;

// Where the merge puts the sorted records. By default a file of its own in the sort's
// directory (sorted.points); a job that writes its container to a regular file hands
// the container's points section instead (pipeline/points_in_output.hpp), so the
// points are on disk once.
class SortedSink {
 public:
  virtual ~SortedSink() = default;
  // The next records, `bytes` of them, in label order.
  virtual void write(const void* data, std::size_t bytes) = 0;
  // Every record is written and `result` is complete but for where the records are:
  // sets its path, offset and crc32c (of the records' bytes); synced when `sync`.
  virtual void finish(SortedPoints& result, bool sync) = 0;
};

struct PointSortOptions {
  std::size_t memory_bytes = std::size_t(1) << 30;  // the ceiling, when no ledger is given
  // The job's ledger (pipeline/memory_budget.hpp): the sort takes its shares from it
  // once pass 1 has counted the points. Null: a ledger of memory_bytes of its own.
  MemoryBudget* budget = nullptr;
  std::size_t run_points = 0;  // points per sorted run; 0: from the ledger
  // Called once the count and bounding box are known, before any sorted run is
  // written: a plan that cannot hold the job is refused here (it throws).
  std::function<void(const SortProgress&)> on_scanned;
  bool progress = true;
  // A resumable sort: run files are fsynced and kept (the caller removes them once it
  // has the merged file), `resume` holds (in) what an earlier process finished and
  // (out) what this one did, and `on_step` sees it after pass 1 and after each run.
  SortProgress* resume = nullptr;
  std::function<void(const SortProgress&)> on_step;
  // Opens where the merge writes, given what is known before it (the count, the
  // layout, the bounding box, the axis); null: sorted.points in the sort's directory.
  std::function<std::unique_ptr<SortedSink>(const SortedPoints&)> open_sink;
};

struct SortedPoints {
  std::string path;                 // the sorted file: `count` records of `layout` from byte `offset` on
  std::uint64_t offset = 0;         // 0 for a file of its own; the points section's payload in a container
  std::uint64_t header_memory = 0;  // in a container: the budget its header names (pipeline/stage_sort.hpp)
  RecordLayout layout;
  std::uint64_t count = 0;        // distinct points
  std::uint64_t input_count = 0;  // points read
  std::uint64_t duplicates = 0;   // input_count - count
  int axis = 0;                   // the longest axis of the bounding box
  double bbox_min[3] = {0, 0, 0}, bbox_max[3] = {0, 0, 0};
  std::vector<std::uint64_t> hull_labels;  // labels of the global convex hull's vertices (sorted)
  std::uint32_t crc32c = 0;                // of the sorted file's bytes
  std::size_t runs = 0;
  double seconds_scan = 0, seconds_runs = 0, seconds_merge = 0;
  StageTime time_scan, time_runs, time_merge;  // the same phases' wall and busy thread-seconds
};

// Sorts the points of `input` into a new file in `dir` (with its runs and, for stdin,
// a spool of the input beside it). Throws InputError for bad input (from the reader)
// and IoError for I/O failures; the caller owns `dir` and removes it (a TempDir, or a
// checkpoint's directory).
SortedPoints sort_points(const std::string& input, const io::PointReadOptions& read_options,
                         const PointSortOptions& options, const std::string& dir);

// Strict weak order of the sorted file along `axis`.
inline bool sorted_before(const SortedPoint& a, const SortedPoint& b, int axis) {
  for (int k = 0; k < 3; ++k) {
    const int c = (axis + k) % 3;
    if (a.xyz[c] != b.xyz[c]) return a.xyz[c] < b.xyz[c];
  }
  return a.original < b.original;
}
// The same order on the file's records (float32 coordinates compare as their doubles).
template <class R>
bool record_before(const R& a, const R& b, int axis) {
  for (int k = 0; k < 3; ++k) {
    const int c = (axis + k) % 3;
    const double x = a.coord(c), y = b.coord(c);
    if (x != y) return x < y;
  }
  return a.original() < b.original();
}

}  // namespace tetstream::pipeline
