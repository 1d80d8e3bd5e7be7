#pragma once
// `tetstream run`: the whole out-of-core job, from a point file to a .tets container.
//
// run_job checks the user's files, opens or refuses the checkpoint, and runs the job's
// stages, each an object with a lifecycle (prepare from the checkpoint, run, commit
// its record; pipeline/stage.hpp):
//   SortStage         (stage_sort.hpp)         external sort along the long axis,
//                                              duplicates merged, hull candidates
//   IndexStage        (stage_index.hpp)        the sorted file mapped, its spatial
//                                              index, the global hull's points
//   TriangulateStage  (stage_triangulate.hpp)  segments cut into zones, each a window,
//                                              kernel, exactness check, repair and
//                                              minimum vertex filter
//   WriteStage        (stage_write.hpp)        frames by minimum label, the compressed
//                                              container on its own thread
#include "io/point_reader.hpp"
#include "pipeline/util/memory_budget.hpp"
#include "pipeline/util/stage_time.hpp"
#include "pipeline/window/zone_plan.hpp"

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace tetstream::pipeline {

struct RunOptions {
  std::string input;   // a point file, or "-" for stdin
  std::string output;  // the .tets container
  io::PointReadOptions read;
  std::uint64_t memory_bytes = std::uint64_t(1) << 30;
  // A job run inside another (a periodic job's padded job): its caller tells the user
  // what is kept and how to resume; the user's --memory, and what the caller holds
  // beside this job, name the figures of a refusal (PlanOptions).
  bool nested = false;
  std::uint64_t memory_stated = 0, memory_reserved = 0;
  std::uint64_t points_stated = 0;  // the user's points among the input's (0: all)
  // The frames the output stage writes when they are not this job's budget's: a
  // periodic job's keep writes frames of the user's --memory (the header's), larger
  // than the padded job's smaller budget gives, and the writer's share must hold
  // them. 0: MemoryBudget::frame_tets_for the header's budget.
  std::size_t frame_tets = 0;
  std::string tmpdir;  // empty: the output's directory
  int threads = 0;     // 0: all cores
  // Buffer thickness in point spacings. Thinner buffers insert fewer redundant points
  // and leave more tets to the emptiness queries; 1.5 is where the two costs meet on
  // uniform points (scripts/bench-pipeline --buffer compares others).
  double buffer_spacings = 1.5;
  // The output's labels (docs/format.md §1): true (the default), format 2's bricks
  // along a space-filling curve (version 2, pipeline/write/label_order.hpp: 1.5-1.8
  // bytes a tet at any size, against 3.5 at 10^8 in the sort's order); false, the
  // sort's order (version 1). The tets are the same; their labels and the points'
  // order are not.
  bool brick_labels = true;
  std::uint64_t segment_points = 0;   // labels a segment owns; 0: from the memory budget (tests force many segments)
  std::uint64_t sort_run_points = 0;  // 0: from the memory budget (tests force many runs)
  // Zones per segment (strips across the sort axis, zone_plan.hpp plan_for_budget): 0 picks
  // the number that wastes the least on buffers for the budget. The zones of all
  // segments are triangulated `threads` at a time. The output's bytes depend on
  // neither this nor the thread count.
  int zones = 0;
  // Where the point index lives (IndexStage): in memory (about 7.5 bytes a point), or
  // in a file of the work directory whose pages are held by region within a share
  // of the budget (index_disk_share). kAuto: the file when the index would take more
  // than an eighth of the budget. The output's bytes do not depend on it.
  enum class IndexPlacement { kAuto, kMemory, kDisk };
  IndexPlacement index = IndexPlacement::kAuto;
  bool progress = true;
  // Checkpoints (pipeline/checkpoint.hpp): the job keeps its working files and its
  // progress in OUTPUT's file name + ".ckpt", a directory it makes in `checkpoint_dir`
  // (default: tmpdir, else the output's directory), and
  // can be resumed after a crash, kill -9, Ctrl-C or a full disk. An existing
  // checkpoint is continued with `resume`, discarded with `force`, and otherwise
  // refused. Off (or stdin input): a private temporary directory, removed at the end.
  bool checkpoint = true;
  std::string checkpoint_dir;
  bool resume = false;
  bool force = false;

  void validate() const;  // throws UsageError
  // Whether a job of `points` points keeps its point index on disk (`index`, above).
  bool index_on_disk(std::uint64_t points) const;
  // What the zone plan reads of these options (pipeline/window/zone_plan.hpp).
  PlanOptions plan_options() const {
    return {memory_bytes,  buffer_spacings, segment_points, zones,
            memory_stated, memory_reserved, points_stated,  frame_tets};
  }
};

struct RunSummary {
  std::uint64_t input_points = 0, points = 0, duplicates = 0;
  std::uint64_t segments = 0, zones = 0, segment_labels = 0, window_points = 0, repair_points = 0;
  std::uint64_t hull_vertices = 0, range_failures = 0, queries = 0, rounds_max = 0;
  std::uint64_t query_points = 0;         // exact conflict tests the queries made
  std::uint64_t tets_by_query = 0;        // tets whose certificate was an emptiness query
  std::uint64_t tets_by_wall = 0;         // tets certified by the wall
  std::uint64_t tets_by_rim = 0;          // tets certified by the rim
  std::uint64_t tets_by_neighbour = 0;    // tets a finished zone had certified (the rest: by the range test)
  std::uint64_t rim_published = 0;        // rim tets finished zones handed to the running ones
  std::uint64_t rim_no_room = 0;          // rim tets finished zones offered to a full table
  std::uint64_t rim_from_neighbours = 0;  // rim tets the running zones found there (no ball, no query)
  std::uint64_t rim_rechecks = 0;         // rim tets left unproved by a round, checked again in the next
  std::uint64_t queries_spared = 0;       // queued tets in conflict with a repair point the round had found (no query)
  // The queries that found no conflict, by how far their balls reached past the
  // window's keys (SegmentStats): none, under half a segment, one, two, farther.
  std::uint64_t empty_reach_none = 0, empty_reach_half = 0, empty_reach_one = 0, empty_reach_two = 0,
                empty_reach_farther = 0;
  // 2 MiB regions of the sorted file that the queries' reads mapped and that were
  // handed back to keep them within their share of the budget (this process's)
  std::uint64_t query_region_releases = 0;
  // The redundant insertions by cause (SegmentStats): sort-axis buffers, the strip
  // buffers of parallel zones, hull vertices outside the window; and repair_points.
  std::uint64_t segment_buffer_points = 0, zone_buffer_points = 0, hull_window_points = 0;
  std::uint64_t neighbour_points = 0;           // held from a zone's start: its finished neighbours' rim tets' vertices
  double seconds_build = 0, seconds_check = 0;  // kernel builds and exactness checks, summed over segments
  std::uint64_t tets = 0, output_bytes = 0;
  std::uint64_t disk_planned_bytes = 0;  // pipeline/disk_plan.hpp; 0: not planned (unknown count, resumed)
  // The largest disk use of the job's own files (its working directory and partial
  // output), sampled at stage boundaries and checkpoints: pipeline/disk_meter.hpp.
  // A resumed job's covers its own process only.
  std::uint64_t disk_peak_bytes = 0;
  std::uint64_t tet_bytes = 0;  // of the tet frames alone (the file also holds the points)
  int axis = 0;
  bool resumed = false;                // continued an earlier process's checkpoint
  std::uint64_t segments_resumed = 0;  // segments that process had written
  // Wall clock. seconds_write: the segment loop waiting on the writer stage (a full
  // queue, checkpoints) and the writer's finish; its own work is seconds_writer_busy.
  double seconds_sort = 0, seconds_triangulate = 0, seconds_write = 0, seconds_total = 0;
  double seconds_index = 0;        // the indexes and the global hull (under mpirun: the slowest rank)
  double seconds_segments = 0;     // summed over segments (more than the wall time with threads)
  double seconds_writer_busy = 0;  // the writer thread compressing and writing (overlapped)
  double seconds_writer_wait = 0;  // the segment loop blocked on the writer (full queue, drains)
  // Each stage's wall time and busy thread-seconds (pipeline/util/stage_time.hpp), in
  // the job's order: "sort" (and its phases "sort.scan", "sort.runs", "sort.merge"),
  // "index" (and "index.keys", "index.build", "index.hull"), "plan", "triangulate"
  // (the segments, with the writer's work overlapped), "tail" (from the last segment
  // handed to the writer to the output's rename: the frames still queued), "total".
  // Empty for a job under mpirun.
  std::vector<std::pair<std::string, StageTime>> stages;
  // The ledger (pipeline/memory_budget.hpp): --memory after any cap, and each share as
  // planned for this input (empty when a finished checkpoint was only collected).
  std::uint64_t memory_ceiling = 0;
  std::vector<MemoryBudget::Share> memory_shares;
  // The process's resident peak when the job ended (pipeline/util/resident_memory.hpp,
  // VmHWM: the sort, the triangulation and the writer alike); 0 where the kernel does
  // not say.
  std::uint64_t memory_peak_bytes = 0;
  // A job under MPI (pipeline/run_distributed.hpp): each rank's part, in rank order
  // (empty for one process). Memory figures above are rank 0's (--memory is per rank).
  struct Rank {
    std::uint64_t first_label = 0, end_label = 0;  // the labels whose tets it wrote
    std::uint64_t segments = 0, zones = 0, tets = 0;
    std::uint64_t frame_bytes = 0;    // of its frames
    std::uint64_t message_bytes = 0;  // it sent to the other ranks (Communicator::bytes_sent)
    double expected_cost_share = 0;   // of the job's expected cost (pipeline/rank_cost.hpp) in its labels
    double seconds_index = 0, seconds_triangulate = 0, seconds_write = 0;
  };
  std::vector<Rank> ranks;
  double redundant_ratio() const {  // points inserted beyond one per point, per point
    return points ? double(window_points + repair_points) / double(points) - 1.0 : 0.0;
  }
  // The zones' strip buffers as a share of all insertions: the insertion work that
  // splitting segments into parallel zones adds (an insertion costs about the same
  // wherever its point lies).
  double zone_buffer_share() const {
    const double inserted = double(window_points + repair_points);
    return inserted > 0 ? double(zone_buffer_points) / inserted : 0.0;
  }
};

RunSummary run_job(const RunOptions& options);

// Where `options` keeps its checkpoint (whether or not one exists).
std::string checkpoint_directory(const RunOptions& options);

// Parses "4G", "512M", "1.5G", "100000" (bytes). Throws UsageError.
std::uint64_t parse_memory_size(const std::string& text);

}  // namespace tetstream::pipeline
