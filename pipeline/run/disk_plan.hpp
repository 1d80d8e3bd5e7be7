#pragma once
// The disk a job will need, planned from the input's point count before any work, so a
// disk that cannot hold the job is refused with the figures instead of filling up
// hours in (docs/safety.md, "Budgets never cost you the work done").
//
// Bytes per input point, by file (a planning bound, not a measurement), with r the
// record of the sorted points, the container's PNTS record (docs/format.md 3.4):
// r = 12 (float32 input) or 24 (float64), + 4 for the original index (+ 8 past 2^32
// points): 28 for float64 input, 16 for float32.
//   the sort's runs  r, in the work directory; the merge gives their space back as it
//                    reads them (holes punched), so runs and merged points together
//                    stay near r, plus the punching's step (16 MiB a run) and the
//                    blocks in flight: planned as r/64 + 64 MiB;
//   the points       r, once: the merge writes them into the output's points section
//                    (a file of the work directory, sorted.points, only when the output
//                    is standard output);
//   the tets         4 bytes a tet and 7 tets a point (measured: 1.5-3.5 bytes a tet,
//                    5.8-6.8 tets a point): 28;
//   a checkpoint     the frame being filled, twice (the old pending file goes after the
//                    state that replaces it): 32 bytes a tet, at most a frame (2^18
//                    tets and a group's overrun), and 1 MiB for the state and slack.
// On one filesystem the peak is r N + 28 N + the checkpoint (the end; the merge's
// r N + r N / 64 + 64 MiB when larger): 56 bytes a point for float64, 44 for float32
// (it was 32 + 28 + 28 = 88 for both before the points went into the output). On two,
// the work directory needs the runs (r N + slack) and the checkpoint, the output's
// r N + 28 N. Where the filesystem cannot punch holes (EOPNOTSUPP) the merge holds
// 2 r N for a moment: not planned.
// Under mpirun (pipeline/run_distributed.hpp) the work directory holds more, for the
// whole triangulation: the shared point index (8 bytes a point) and the fragments of
// ranks 1..K-1 (their tets, 28 (K - 1) / K bytes a point) until they are placed;
// `more_work` is that, per point; for one process with its point index on disk (`run
// --index`), the index's file, 8 bytes a point; and for container version 2 (`run
// --labels bricks`, the default) the label order's file, 4 bytes a point.
#include <cstdint>
#include <string>
#include <vector>

namespace tetstream::pipeline {

struct DiskNeed {
  std::string dir;              // a directory on the filesystem
  std::uint64_t need = 0;       // bytes the job will write there at its peak
  std::uint64_t available = 0;  // bytes free for this user now (statvfs f_bavail)
};

// One entry per filesystem the job writes to: the work directory's parent and the
// output's directory (none for an output streamed to stdout). Throws IoError when a
// directory cannot be examined.
// `float32`: the input's coordinates are float32 (PointReader::float32_input).
std::vector<DiskNeed> plan_disk(std::uint64_t points, bool float32, const std::string& work_parent,
                                const std::string& output_dir, bool output_to_stdout, bool checkpointed,
                                std::uint64_t more_work = 0);
// The work directory's bytes a point beyond one process's under K ranks (above).
std::uint64_t distributed_work_bytes_per_point(int ranks);
// Throws IoError naming every filesystem that cannot hold its share:
// "needs 41.2 GiB in /scratch, 38.0 GiB free; ...".
void check_disk(const std::vector<DiskNeed>& plan);

}  // namespace tetstream::pipeline
