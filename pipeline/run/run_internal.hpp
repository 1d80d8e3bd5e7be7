#pragma once
// What the single-process job (run.cpp) and the distributed one (run_distributed.cpp)
// share before their stages: the options as run, where working files go, the disk's
// check, the stale directories of killed jobs. Internal to pipeline/.
#include "io/output_file.hpp"
#include "pipeline/files/checkpoint.hpp"
#include "pipeline/run/output_stage.hpp"
#include "pipeline/run/run.hpp"
#include "pipeline/run/stage.hpp"
#include "pipeline/sort/point_sort.hpp"
#include "pipeline/util/memory_budget.hpp"
#include "pipeline/window/sorted_view.hpp"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

namespace tetstream::pipeline::detail {

// Makes the stage that takes the triangulation's segments (output_stage.hpp) from what
// the write stage is made of: run_job's is the write stage, a periodic job's its keep.
using OutputStageFactory = std::function<std::unique_ptr<OutputStage>(
    const StageContext&, const SortedPoints&, const SortedView&, const TriangulateShares&, const io::OutputClaim*)>;
// run_job (run.hpp) with another output stage; null: the write stage.
RunSummary run_job(const RunOptions& requested, const OutputStageFactory& make_output);

// The options validated, --memory capped at the machine's physical memory (with a warning).
RunOptions capped_options(const RunOptions& requested);
// Where a job's working files go: --tmpdir, else the output's directory.
std::string work_parent(const RunOptions& options);
// The disk the job needs, planned from the input's point count and checked against
// each filesystem's free space before any work (IoError with the figures); 0 when the
// count is unknown (text, stdin).
// `ranks`: the job's processes (the work directory holds more under mpirun: disk_plan.hpp).
std::uint64_t plan_and_check_disk(const RunOptions& o, const std::string& work_parent, bool checkpointed,
                                  int ranks = 1);
// Removes the temporary directories that killed jobs left in `parent`.
void remove_stale_temporary_dirs(const std::string& parent);

// What the identity of a job is made of (the input's fingerprint and the options that
// change the output's bytes), and what differs between two ("" when nothing does).
nlohmann::json job_identity(const RunOptions& o);
std::string identity_difference(const nlohmann::json& saved, const nlohmann::json& now);

inline constexpr const char* kHowToRestart = "rerun with --force to discard it and start over";

// Runs f, which reads the checkpoint; a missing field or any other damage becomes a
// DamagedCheckpoint that says how to start over.
template <class F>
void trusting_checkpoint(const Checkpoint& checkpoint, F&& f) {
  try {
    f();
  } catch (const nlohmann::json::exception& e) {
    throw DamagedCheckpoint(checkpoint.dir() + "/state.json: damaged checkpoint (" + e.what() + "); " + kHowToRestart);
  } catch (const DamagedCheckpoint& e) {
    throw DamagedCheckpoint(std::string(e.what()) + "; " + kHowToRestart);
  }
}

// The checkpoint of a job, opened (made, locked, read) under --resume / --force as the
// user asked: its state (holding at least the job's identity), the disk planned for a
// new job, and, when the checkpointed job had finished (only the checkpoint's removal
// was cut short), its summary, the checkpoint removed.
struct OpenedJob {
  nlohmann::json state = nlohmann::json::object();
  std::uint64_t disk = 0;
  std::optional<RunSummary> finished;
};
// `ranks`: the job's processes (the disk plan: disk_plan.hpp).
OpenedJob open_checkpointed_job(const RunOptions& options, Checkpoint& checkpoint, const io::OutputClaim& claim,
                                int ranks = 1);

// Thrown by an output stage that gives the job up for its caller to run otherwise (a
// periodic job whose certificate fails: its margin doubles). Nothing of it is worth
// resuming: rethrow_job_failure removes the checkpoint and the partial output.
struct JobAbandoned : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// In a catch block: rethrows the job's failure, after removing the checkpoint and the
// partial output when nothing is worth resuming (bad input, a budget refused before
// the sort), or with what to do next (the work kept for --resume).
[[noreturn]] void rethrow_job_failure(Checkpoint& checkpoint, const RunOptions& options);

}  // namespace tetstream::pipeline::detail
