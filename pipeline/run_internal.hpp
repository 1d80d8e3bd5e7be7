#pragma once
// What the single-process job (run.cpp) and the distributed one (run_distributed.cpp)
// share before their stages: the options as run, where working files go, the disk's
// check, the stale directories of killed jobs. Internal to pipeline/.
#include "pipeline/run.hpp"

#include <cstdint>
#include <string>

namespace tetstream::pipeline::detail {

// The options validated, --memory capped at the machine's physical memory (with a warning).
RunOptions capped_options(const RunOptions& requested);
// Where a job's working files go: --tmpdir, else the output's directory.
std::string work_parent(const RunOptions& options);
// The disk the job needs, planned from the input's point count and checked against
// each filesystem's free space before any work (IoError with the figures); 0 when the
// count is unknown (text, stdin).
std::uint64_t plan_and_check_disk(const RunOptions& o, const std::string& work_parent, bool checkpointed);
// Removes the temporary directories that killed jobs left in `parent`.
void remove_stale_temporary_dirs(const std::string& parent);

}  // namespace tetstream::pipeline::detail
