#pragma once
// The disk a job will need, planned from the input's point count before any work, so a
// disk that cannot hold the job is refused with the figures instead of filling up
// hours in (docs/safety.md, "Budgets never cost you the work done").
//
// Bytes per input point, by file (a planning bound, not a measurement):
//   work directory   the sort's runs, 32 (a SortedPoint each), and the sorted file, 32:
//                    both exist at the merge; the runs go after it, the sorted file
//                    stays to the end;
//   output           the points section, 24 + 4 (float64 and a 32-bit original index
//                    below 2^32 points, else + 8), and the tets at 4 bytes a tet and 7
//                    tets a point (measured: 2.2-3.5 bytes a tet, 5.8-6.8 tets a point).
//   a checkpoint     the frame being filled, twice (the old pending file goes after the
//                    state that replaces it): 32 bytes a tet, at most a frame (2^18
//                    tets and a group's overrun), and 1 MiB for the state and slack.
// On one filesystem the peak is the larger of the merge (64) and the end (32 + output);
// on two, each has its own.
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
std::vector<DiskNeed> plan_disk(std::uint64_t points, const std::string& work_parent, const std::string& output_dir,
                                bool output_to_stdout, bool checkpointed);
// Throws IoError naming every filesystem that cannot hold its share:
// "needs 41.2 GiB in /scratch, 38.0 GiB free; ...".
void check_disk(const std::vector<DiskNeed>& plan);

}  // namespace tetstream::pipeline
