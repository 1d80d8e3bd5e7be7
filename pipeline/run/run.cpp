#include "pipeline/run/run.hpp"

#include "core/error.hpp"
#include "io/output_file.hpp"
#include "io/point_format.hpp"
#include "io/point_reader.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/files/checkpoint.hpp"
#include "pipeline/run/disk_plan.hpp"
#include "pipeline/util/communicator.hpp"
#include "pipeline/util/memory_budget.hpp"
#include "pipeline/util/progress.hpp"
#include "pipeline/util/resident_memory.hpp"
#include "pipeline/run/run_internal.hpp"
#include "pipeline/run/stage.hpp"
#include "pipeline/run/stage_index.hpp"
#include "pipeline/run/stage_sort.hpp"
#include "pipeline/run/stage_triangulate.hpp"
#include "pipeline/run/stage_write.hpp"
#include "pipeline/files/temp_files.hpp"
#include "pipeline/window/zone_plan.hpp"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <cctype>
#include <cmath>
#include <filesystem>
#include <optional>
#include <unistd.h>
#include <omp.h>

namespace tetstream::pipeline {

std::uint64_t parse_memory_size(const std::string& text) {
  // As people write sizes: 512M, 512m, 512MB, 512MiB, 1.5G, 1g, 4096K, 100000 (bytes).
  // Every unit is binary (M = MB = MiB = 2^20): a memory budget is counted in pages.
  std::size_t used = 0;
  double value = 0;
  try {
    value = std::stod(text, &used);
  } catch (const std::exception&) {
    throw UsageError("bad memory size '" + text + "': expected e.g. 512M, 4G, 1.5G");
  }
  std::string unit = text.substr(used);
  for (char& c : unit) c = char(std::toupper(static_cast<unsigned char>(c)));
  if (unit.size() == 3 && unit.substr(1) == "IB")
    unit = unit.substr(0, 1);  // KiB, MiB, ...
  else if (unit.size() == 2 && unit[1] == 'B')
    unit = unit.substr(0, 1);  // KB, MB, ...
  double scale = 0;
  if (unit == "" || unit == "B")
    scale = 1;
  else if (unit == "K")
    scale = 1024.0;
  else if (unit == "M")
    scale = 1024.0 * 1024;
  else if (unit == "G")
    scale = 1024.0 * 1024 * 1024;
  else if (unit == "T")
    scale = 1024.0 * 1024 * 1024 * 1024;
  else
    throw UsageError("bad memory size '" + text + "': unknown unit '" + text.substr(used) + "' (use K, M, G, T)");
  if (!(value > 0) || !std::isfinite(value) || value * scale >= 0x1p63)
    throw UsageError("bad memory size '" + text + "': must be positive and below 8 EiB");
  return std::uint64_t(value * scale);
}

bool RunOptions::index_on_disk(std::uint64_t points) const {
  if (index != IndexPlacement::kAuto) return index == IndexPlacement::kDisk;
  return index_crowds_budget(points, memory_bytes);
}

void RunOptions::validate() const {
  if (input.empty()) throw UsageError("no input given");
  if (output.empty()) throw UsageError("no output given (-o OUT.tets)");
  if (memory_bytes < (std::uint64_t(32) << 20))
    throw UsageError("--memory " + std::to_string(memory_bytes >> 20) + "M is too small: at least 32M");
  if (!(buffer_spacings >= 0) || buffer_spacings > 1000) throw UsageError("--buffer must be in [0, 1000]");
  read.validate();
}

using nlohmann::json;

namespace {
std::string base_name(const std::string& path) { return std::filesystem::path(path).filename().string(); }
}  // namespace

namespace detail {

// What makes two processes the same job: the input (its fingerprint) and every option
// that changes the output's bytes. The thread count and zone size are not among
// them: the bytes do not depend on them.
json job_identity(const RunOptions& o) {
  // Every file of the input (several files read as one are all fingerprinted).
  json more = json::array();
  for (const std::string& f : o.read.more_inputs) more.push_back({{"file", f}, {"fingerprint", fingerprint_file(f)}});
  return {{"input", o.input},
          {"input_fingerprint", {fingerprint_file(o.input), more}},
          {"output", std::filesystem::absolute(o.output).lexically_normal().string()},
          {"memory", o.memory_bytes},
          {"buffer_spacings", o.buffer_spacings},
          {"sort_run_points", o.sort_run_points},
          {"labels", o.brick_labels ? "bricks" : "sorted"},
          {"read", o.read.identity()}};
}

// One line naming what differs between a checkpoint's job and this one.
std::string identity_difference(const json& saved, const json& now) {
  if (saved.at("input") != now.at("input"))
    return "the input was " + saved.at("input").get<std::string>() + ", now " + now.at("input").get<std::string>();
  if (saved.at("input_fingerprint") != now.at("input_fingerprint"))
    return "the input " + now.at("input").get<std::string>() + " changed (size, time or contents) since the checkpoint";
  // Not "memory": a resumed job may take another budget (the header keeps the budget
  // it was written with, and so do the frames; see WriteStage::prepare).
  for (const char* key : {"output", "buffer_spacings", "sort_run_points", "read"})
    if (saved.at(key) != now.at(key))
      return std::string("option '") + key + "' was " + saved.at(key).dump() + ", now " + now.at(key).dump();
  // (A checkpoint made before --labels existed was of sorted labels.)
  if (saved.value("labels", "sorted") != now.value("labels", "sorted"))
    return "option '--labels' was " + saved.value("labels", "sorted") + ", now " + now.value("labels", "sorted");
  return "";
}
}  // namespace detail

namespace {
using namespace detail;

// The job: the stages of `run` wired together (pipeline/stage.hpp says what each
// stage's prepare, run and commit do). Owns what the stages share: the checkpoint
// state, the memory ledger and the thread count, which it hands to each stage.
class Job {
 public:
  Job(const RunOptions& options, std::string dir, Checkpoint* checkpoint, json state, const io::OutputClaim* claim,
      const OutputStageFactory& make_output)
      : make_output_(make_output),
        options_(options),
        dir_(std::move(dir)),
        checkpoint_(checkpoint),
        state_(std::move(state)),
        claim_(claim),
        threads_(options.threads > 0 ? options.threads : omp_get_max_threads()),
        budget_(options.memory_bytes, 0, threads_, omp_get_num_procs()) {}
  RunSummary run();

 private:
  const OutputStageFactory& make_output_;  // null: the write stage
  const RunOptions& options_;
  std::string dir_;
  Checkpoint* checkpoint_;        // null: not resumable
  json state_;                    // what the checkpoint holds (maintained even without one)
  const io::OutputClaim* claim_;  // the output, locked for this job since it began
  const int threads_;             // the zones triangulated at once
  MemoryBudget budget_;           // the ledger: every stage's share of --memory
  RunSummary summary_;
  StageClock::time_point start_ = StageClock::now();
};

RunSummary Job::run() {
  RunSummary& summary = summary_;
  summary.resumed = state_.contains("sort") || state_.contains("sorted");
  // The job's files on disk, measured at each stage boundary and checkpoint.
  DiskMeter disk(dir_, io::is_std_stream(options_.output) ? "" : options_.output + ".partial");
  const StageContext context{options_, dir_, checkpoint_, state_, &disk};

  const StageMeter job_meter;
  StageMeter meter;
  auto stage_done = [&](const char* name) {
    summary.stages.emplace_back(name, meter.elapsed());
    meter.restart();
  };

  // ---- sort: the external sort, or what the checkpoint kept of it ----
  SortStage sort(context, budget_, threads_, claim_);
  sort.prepare();
  const SortedPoints& sorted = sort.run();
  sort.commit();
  disk.sample();
  summary.input_points = sorted.input_count;
  summary.points = sorted.count;
  summary.duplicates = sorted.duplicates;
  summary.axis = sorted.axis;
  summary.seconds_sort = seconds_since(start_);
  stage_done("sort");
  summary.stages.emplace_back("sort.scan", sorted.time_scan);  // zero for phases a checkpoint kept
  summary.stages.emplace_back("sort.runs", sorted.time_runs);
  summary.stages.emplace_back("sort.merge", sorted.time_merge);
  spdlog::info("sorted {} points ({} duplicates merged) along {} in {} runs, {:.1f}s", sorted.count, sorted.duplicates,
               "xyz"[sorted.axis], sorted.runs, summary.seconds_sort);
  if (sorted.count < 4) throw InputError(options_.input + ": fewer than 4 distinct points");

  // ---- index: the spatial index and the global hull ----
  IndexStage index(sorted, threads_);
  const auto index_start = StageClock::now();
  index.prepare();
  if (options_.index_on_disk(sorted.count)) {
    const std::uint64_t share = index_disk_share(options_.memory_bytes);
    spdlog::debug("point index: on disk (index.shared in the work directory), at most {} of it resident",
                  human_bytes(double(share)));
    index.run_on_disk(dir_ + "/index.shared", share);
  } else {
    spdlog::debug("point index: in memory");
    index.run();
  }
  summary.seconds_index = seconds_since(index_start);
  stage_done("index");
  for (const auto& phase : index.phases()) summary.stages.push_back(phase);
  summary.hull_vertices = index.view().hull_points.size();

  // The triangulation's shares of the ledger, from the indexes as built, with the
  // frames of the budget the output was started with.
  budget_.set_frame_tets(options_.frame_tets != 0 ? options_.frame_tets
                                                  : MemoryBudget::frame_tets_for(header_memory(state_, options_)));
  if (options_.brick_labels) budget_.set_label_order_bytes(BrickReorder::job_bytes(sorted.count));
  const TriangulatePlan plan = plan_triangulation(index, options_, budget_, threads_);
  stage_done("plan");

  // ---- write, started before the triangulation feeds it: the output, new or resumed ----
  // Declared before the triangulation that feeds it, so destroyed after it on a failure.
  const std::unique_ptr<OutputStage> output =
      make_output_ ? make_output_(context, sorted, index.view(), plan.shares, claim_)
                   : std::make_unique<WriteStage>(context, sorted, index.view(), plan.shares, claim_);
  OutputStage& write = *output;
  write.prepare();
  write.run();
  disk.sample();

  // ---- triangulate: the segments' zones, `threads` at a time, written in order ----
  TriangulateStage triangulate(options_, index, plan.zones, plan.shares.query_page_bytes, plan.shares.shared_rim_bytes,
                               threads_);
  triangulate.prepare(write.first_label(), write.segments_done());
  budget_.plan_triangulate(plan.shares.index_bytes, triangulate.window_bytes());  // the windows as measured
  triangulate.run(write);
  stage_done("triangulate");
  write.commit();
  disk.sample();
  write.finish();
  summary.disk_peak_bytes = std::max(disk.peak(), disk.sample());
  for (const auto& phase : write.phases()) summary.stages.push_back(phase);

  record_work(write.work(), summary);
  summary.segments_resumed = write.segments_resumed();
  summary.segments = write.segments_resumed() + triangulate.segments();
  summary.zones = triangulate.zones();
  summary.seconds_triangulate = triangulate.seconds();
  summary.query_region_releases = triangulate.query_region_releases();
  summary.seconds_write = write.seconds();
  summary.seconds_writer_busy = write.busy_seconds();
  summary.seconds_writer_wait = write.producer_wait_seconds();
  summary.output_bytes = write.bytes_written();
  summary.tet_bytes = write.tet_bytes();
  summary.seconds_total = seconds_since(start_);
  stage_done("tail");
  summary.stages.emplace_back("total", job_meter.elapsed());
  summary.memory_ceiling = budget_.ceiling();
  summary.memory_shares = budget_.shares();
  summary.memory_peak_bytes = peak_resident_bytes();
  return summary;
}

}  // namespace

namespace detail {
// Where a job's working files go: --tmpdir, else the output's directory.
std::string work_parent(const RunOptions& options) {
  std::string dir = options.tmpdir;
  if (dir.empty() && !io::is_std_stream(options.output))
    dir = std::filesystem::path(options.output).parent_path().string();
  return dir.empty() ? "." : dir;
}
}  // namespace detail
using detail::work_parent;

std::string checkpoint_directory(const RunOptions& options) {
  // Always a directory of the job's own, inside the one the user named: the job may
  // remove what it made, never the user's directory (docs/safety.md).
  const std::string parent = options.checkpoint_dir.empty() ? work_parent(options) : options.checkpoint_dir;
  return parent + "/" + base_name(options.output) + ".ckpt";
}

namespace detail {

// The machine's physical memory: a larger --memory is capped there (a budget is a
// ceiling, and buffers sized from 1T fail to allocate).
std::uint64_t physical_memory_bytes() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
  return pages > 0 && page > 0 ? std::uint64_t(pages) * std::uint64_t(page) : ~std::uint64_t(0);
}

// The disk the job needs, from the input's point count (a header or the file's size;
// unknown for text and stdin, then not planned), checked before any work: IoError
// with the figures when a filesystem cannot hold its share.
std::uint64_t plan_and_check_disk(const RunOptions& o, const std::string& work_parent, bool checkpointed, int ranks) {
  if (io::is_std_stream(o.input)) return 0;
  const auto reader = io::open_points(o.input, o.read);
  const std::optional<std::uint64_t> points = reader->count();
  if (!points) return 0;
  std::string out_dir = io::is_std_stream(o.output) ? "" : std::filesystem::path(o.output).parent_path().string();
  if (out_dir.empty()) out_dir = ".";
  // Version 2's label order file (pipeline/write/label_order.hpp), 4 bytes a point, is
  // held from the write stage's start to the points' rewrite at its end.
  const std::uint64_t label_order = o.brick_labels ? 4 : 0;
  const std::vector<DiskNeed> plan =
      plan_disk(*points, reader->float32_input(), work_parent, out_dir, io::is_std_stream(o.output), checkpointed,
                label_order + (ranks > 1                  ? distributed_work_bytes_per_point(ranks)
                               : o.index_on_disk(*points) ? 8
                                                          : 0));
  std::uint64_t need = 0;
  for (const DiskNeed& d : plan) {
    need += d.need;
    spdlog::info("disk: the job will need about {} in {} ({} free)", human_bytes(double(d.need)), d.dir,
                 human_bytes(double(d.available)));
  }
  check_disk(plan);
  return need;
}

// Temporary directories that killed jobs left in `parent` (their lock is free).
void remove_stale_temporary_dirs(const std::string& parent) {
  try {
    for (const StaleWorkDir& stale : find_stale_work_dirs(parent))
      if (!stale.checkpoint && remove_stale_work_dir(stale))
        spdlog::info("removed {}, left by a tetstream job that no longer runs", stale.path);
  } catch (const IoError& e) {
    spdlog::debug("not looking for stale work directories: {}", e.what());
  }
}

RunOptions capped_options(const RunOptions& requested) {
  requested.validate();
  RunOptions options = requested;
  if (const std::uint64_t ram = physical_memory_bytes(); options.memory_bytes > ram) {
    spdlog::warn("--memory {} is more than this machine's {} of memory: capped there",
                 human_bytes(double(options.memory_bytes)), human_bytes(double(ram)));
    options.memory_bytes = ram;
  }
  return options;
}

}  // namespace detail
using namespace detail;

RunSummary run_job(const RunOptions& requested) { return run_job(requested, nullptr); }

RunSummary detail::run_job(const RunOptions& requested, const OutputStageFactory& make_output) {
  RunOptions options = capped_options(requested);
  // The user's files before anything else (docs/safety.md): never the input as the
  // output, never through a link or into a device, and one job per output at a time
  // (the claim's lock is held until the job ends).
  // A container streamed to standard output ("-o -") cannot be resumed (what went
  // down the pipe is gone), and neither can stdin input (it cannot be read again).
  const bool to_stdout = io::is_std_stream(options.output);
  if (to_stdout && options.resume)
    throw UsageError("--resume needs an output file: a job streamed to standard output (-o -) cannot be resumed");
  if (!io::is_std_stream(options.input)) {
    io::refuse_input_as_output(options.input, options.output);
    for (const std::string& more : options.read.more_inputs) io::refuse_input_as_output(more, options.output);
  }
  std::optional<io::OutputClaim> claim;
  if (!to_stdout) claim.emplace(options.output);
  if (!options.checkpoint || io::is_std_stream(options.input) || to_stdout) {
    if (options.checkpoint)
      spdlog::info("the {} is a stream: this job keeps no checkpoint (it cannot be resumed)",
                   to_stdout ? "output" : "input");
    remove_stale_temporary_dirs(work_parent(options));
    const std::uint64_t disk = plan_and_check_disk(options, work_parent(options), false);
    TempDir tmp(work_parent(options), "tetstream-run");
    RunSummary summary;
    try {
      summary = Job(options, tmp.dir(), nullptr, json::object(), claim ? &*claim : nullptr, make_output).run();
    } catch (...) {
      // The sort may have written the points into the partial output before any
      // writer owned it: a job without a checkpoint leaves nothing behind.
      if (claim && claim->created()) remove_file(options.output + ".partial");
      throw;
    }
    summary.disk_planned_bytes = disk;
    return summary;
  }

  const std::string checkpoint_dir = checkpoint_directory(options);
  // What a job killed while removing its checkpoint left beside it (DIR.old-PID-N).
  remove_stale_temporary_dirs(std::filesystem::path(checkpoint_dir).parent_path().string());
  Checkpoint checkpoint(checkpoint_dir);
  OpenedJob opened = open_checkpointed_job(options, checkpoint, *claim);
  if (opened.finished) return *opened.finished;
  try {
    RunSummary summary;
    trusting_checkpoint(checkpoint, [&] {
      summary = Job(options, checkpoint.dir(), &checkpoint, opened.state, &*claim, make_output).run();
    });
    checkpoint.remove();
    summary.disk_planned_bytes = opened.disk;
    return summary;
  } catch (...) {
    rethrow_job_failure(checkpoint, options);
  }
}

namespace detail {

OpenedJob open_checkpointed_job(const RunOptions& options, Checkpoint& checkpoint, const io::OutputClaim& claim,
                                int ranks) {
  OpenedJob opened;
  json& state = opened.state;
  const json identity = job_identity(options);
  checkpoint.create_and_lock();
  if (checkpoint.exists()) {
    if (options.force) {
      spdlog::info("--force: discarding the checkpoint in {}", checkpoint.dir());
      checkpoint.clear();  // the job's files only; the partial output is truncated by the writer
    } else if (!options.resume) {
      throw UsageError(checkpoint.dir() +
                       " holds the checkpoint of an unfinished job: rerun with --resume to continue "
                       "it, or with --force to discard it and start over");
    } else {
      std::string difference;
      trusting_checkpoint(checkpoint, [&] {
        state = checkpoint.load();
        difference = identity_difference(state.at("job"), identity);
      });
      if (!difference.empty())
        throw UsageError("cannot resume from " + checkpoint.dir() + ": " + difference + "; " + kHowToRestart);
      spdlog::info("resuming the job checkpointed in {}", checkpoint.dir());
    }
  } else if (options.resume) {
    spdlog::warn("no checkpoint in {}: starting from the beginning", checkpoint.dir());
  }
  if (state.contains("output") && state["output"].value("finishing", false) && claim.created() &&
      std::filesystem::exists(options.output)) {
    // The job had finished; only the removal of its checkpoint was cut short.
    const io::TetReader finished(options.output);  // throws unless complete
    spdlog::info("the checkpointed job had finished: {} is complete", options.output);
    RunSummary summary;
    record_work(counters_from(state["output"].at("counters")), summary);
    summary.resumed = true;
    summary.segments = summary.segments_resumed = state["output"].at("segments").get<std::uint64_t>();
    summary.points = finished.point_count();
    summary.input_points = finished.header().input_count;
    summary.duplicates = summary.input_points - summary.points;
    summary.output_bytes = finished.file_bytes();
    summary.tet_bytes = finished.tet_bytes();
    checkpoint.remove();
    opened.finished = summary;
    return opened;
  }
  if (!state.contains("job")) {
    const std::string parent = std::filesystem::path(checkpoint.dir()).parent_path().string();
    try {
      opened.disk = plan_and_check_disk(options, parent.empty() ? "." : parent, true, ranks);
    } catch (...) {
      checkpoint.remove();  // made just now, and empty: nothing to resume
      throw;
    }
    state = {{"job", identity}};
    checkpoint.save(state);
  }
  return opened;
}

namespace {
void say_progress_is_kept(const Checkpoint& checkpoint) {
  spdlog::warn("the job's progress is kept in {}: run the same command with --resume to continue", checkpoint.dir());
}
}  // namespace

void rethrow_job_failure(Checkpoint& checkpoint, const RunOptions& options) {
  // Nothing worth resuming: the checkpoint and the partial output go.
  const auto discard = [&] {
    checkpoint.remove();
    remove_file(options.output + ".partial");
  };
  // What is kept is said once, by the job the user ran (a nested job's checkpoint lies
  // inside its caller's, which says it).
  const auto say_kept = [&] {
    if (!options.nested) say_progress_is_kept(checkpoint);
  };
  try {
    throw;
  } catch (const DamagedCheckpoint&) {
    throw;  // left for the user to inspect or --force away
  } catch (const JobAbandoned&) {
    discard();
    throw;
  } catch (const InputError&) {
    discard();  // bad input
    throw;
  } catch (const PeerFailed& e) {
    // Under mpirun, another rank found bad input in its range: as in one process,
    // nothing to resume. Any other failure of a peer keeps the work, as below.
    if (e.code() == ExitCode::kBadInput)
      discard();
    else
      say_kept();
    throw;
  } catch (const BudgetTooSmall&) {
    discard();  // refused after the first pass: nothing was written worth resuming
    throw;
  } catch (const UsageError& e) {
    // A budget too small for the sorted input: the sort's work is kept, and a resume
    // may take another --memory (the message names the one that works).
    if (options.nested) throw;
    throw UsageError(std::string(e.what()) + "; the work so far is kept in " + checkpoint.dir() +
                     ": add --resume with the new --memory");
  } catch (const std::bad_alloc&) {
    if (options.nested) throw;
    throw IoError("out of memory at --memory " + human_bytes(double(options.memory_bytes)) +
                  "; the work so far is kept in " + checkpoint.dir() +
                  ": free memory, or rerun with a smaller --memory and --resume");
  } catch (...) {
    say_kept();
    throw;
  }
}

}  // namespace detail

}  // namespace tetstream::pipeline
