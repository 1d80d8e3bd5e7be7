#include "pipeline/periodic/periodic.hpp"

#include "pipeline/run/summary_json.hpp"

#include "core/error.hpp"
#include "io/output_file.hpp"
#include "io/point_reader.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/distributed/run_distributed.hpp"
#include "pipeline/files/checkpoint.hpp"
#include "pipeline/files/temp_files.hpp"
#include "pipeline/run/run_internal.hpp"
#include "pipeline/periodic/keep.hpp"
#include "pipeline/periodic/keep_stage.hpp"
#include "pipeline/periodic/margin.hpp"
#include "pipeline/periodic/pad.hpp"

#include <nlohmann/json.hpp>
#include <omp.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <optional>
#include <sstream>
#include <thread>

namespace tetstream::pipeline::periodic {

namespace {
using nlohmann::json;

double seconds_since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

constexpr const char* kPadded = "periodic-padded.tets";

// The ordinary job on the padded points in the job's directory `dir` (the input itself
// for the box's points when it is its own wrapped copy, pad.hpp): the same options but
// for the files. Checkpointed when the periodic job is, its checkpoint nested in
// the periodic one's (dir/periodic-padded.tets.ckpt).
RunOptions padded_job(const RunOptions& o, const std::string& dir, bool input_as_is, bool images) {
  RunOptions inner = o;
  inner.input = input_as_is ? o.input : dir + "/periodic-points.f64";
  inner.read = io::PointReadOptions{};
  inner.read.format = io::PointFormat::kRaw;
  inner.read.type = io::ScalarType::kFloat64;
  if (images) inner.read.more_inputs = {dir + "/periodic-images.f64"};
  inner.output = dir + "/" + kPadded;
  inner.tmpdir = dir;
  inner.checkpoint_dir = dir;
  inner.resume = inner.force = false;
  // The keep stage walks the padded tets by the sort's order (a tet's box part by its
  // smallest label's slab): version 1's labels, whatever the caller's default.
  inner.brick_labels = false;
  return inner;
}

// The padded job's work in `dir`: its nested checkpoint (reopened through its lock and
// marker, so only a directory tetstream made, holding only its files, is removed) and
// its output, partial or complete.
void discard_padded_job(const std::string& dir) {
  const std::string nested = dir + "/" + kPadded + ".ckpt";
  std::error_code ec;
  if (std::filesystem::symlink_status(nested, ec).type() != std::filesystem::file_type::not_found) {
    Checkpoint c(nested);
    c.create_and_lock();
    c.remove();
  }
  remove_file(dir + "/" + kPadded);
  remove_file(dir + "/" + kPadded + ".partial");
}

bool exists(const std::string& path) {
  std::error_code ec;
  return std::filesystem::symlink_status(path, ec).type() != std::filesystem::file_type::not_found;
}

json fingerprint_if_there(const std::string& path) { return exists(path) ? fingerprint_file(path) : json(); }

// What of the periodic options changes the output's bytes (the checkpoint's identity
// beside the plain job's: docs/periodic.md). Not --memory: a resumed job may take
// another, and the header keeps the first (as a plain run's does). `keep`: which copy
// of each tet the keep writes (the one whose circumcentre lies in the box of centres):
// a checkpoint of a keep that chose the copies otherwise cannot be continued.
json periodic_identity(const PeriodicOptions& p) {
  return {{"period", p.period}, {"wrap", p.wrap}, {"margin_spacings", p.margin_spacings}, {"keep", "circumcentre"}};
}

std::string header_options(std::uint64_t memory, const PeriodicOptions& p, const std::array<double, 3>& margin) {
  json j;
  j["command"] = "run";
  j["periodic"] = p.period;
  j["margin"] = margin;
  j["memory"] = memory;
  return j.dump();
}

json done_record(const PeriodicSummary& s) {
  return {{"input_points", s.input_points},
          {"points", s.points},
          {"wrapped", s.wrapped},
          {"images", s.images},
          {"tets", s.tets},
          {"attempts", s.attempts},
          {"margin", s.margin},
          {"output_bytes", s.output_bytes}};
}

void from_done_record(const json& j, PeriodicSummary& s) {
  s.input_points = j.at("input_points");
  s.points = j.at("points");
  s.wrapped = j.at("wrapped");
  s.images = j.at("images");
  s.tets = j.at("tets");
  s.attempts = j.at("attempts");
  s.margin = j.at("margin");
  s.output_bytes = j.at("output_bytes");
}

// Rank 0's side of a periodic job: the user's files, the job's directory and its state.
class Root {
 public:
  Root(const RunOptions& options, const PeriodicOptions& periodic, int ranks)
      : options_(options), periodic_(periodic), ranks_(ranks) {}

  // Claims the output, opens the checkpoint (--resume, --force, or refused as a plain
  // run's) or a temporary directory. True when the checkpointed job had finished (its
  // summary in `sum`, the checkpoint removed).
  bool open(PeriodicSummary& sum);
  const std::string& dir() const { return dir_; }
  Checkpoint* checkpoint() { return checkpoint_ ? &*checkpoint_ : nullptr; }
  const io::OutputClaim& claim() const { return *claim_; }
  json& state() { return state_; }
  void save() {
    if (checkpoint_) checkpoint_->save(state_);
  }
  std::uint64_t header_memory() const { return state_.value("memory", options_.memory_bytes); }

 private:
  const RunOptions& options_;
  const PeriodicOptions& periodic_;
  int ranks_;
  std::optional<io::OutputClaim> claim_;
  std::optional<Checkpoint> checkpoint_;
  std::optional<TempDir> tmp_;
  json state_ = json::object();
  std::string dir_;
};

bool Root::open(PeriodicSummary& sum) {
  io::refuse_input_as_output(options_.input, options_.output);
  for (const std::string& more : options_.read.more_inputs) io::refuse_input_as_output(more, options_.output);
  claim_.emplace(options_.output);
  if (!options_.checkpoint) {
    detail::remove_stale_temporary_dirs(detail::work_parent(options_));
    tmp_.emplace(detail::work_parent(options_), "tetstream-run");
    dir_ = tmp_->dir();
    return false;
  }
  checkpoint_.emplace(checkpoint_directory(options_));
  detail::OpenedJob opened = detail::open_checkpointed_job(options_, *checkpoint_, *claim_, ranks_);
  state_ = std::move(opened.state);
  dir_ = checkpoint_->dir();
  if (options_.force) discard_padded_job(dir_);  // --force: the nested checkpoint too
  const json identity = periodic_identity(periodic_);
  if (!state_.contains("periodic")) {
    state_["periodic"] = identity;
    state_["memory"] = options_.memory_bytes;
    save();
    return false;
  }
  if (state_["periodic"] != identity)
    throw UsageError("cannot resume from " + dir_ + ": the periodic options were " + state_["periodic"].dump() +
                     ", now " + identity.dump() + "; " + detail::kHowToRestart);
  if (!state_.contains("done")) return false;
  // Written, renamed into place: only the checkpoint's removal was cut short.
  detail::trusting_checkpoint(*checkpoint_, [&] { from_done_record(state_.at("done"), sum); });
  const io::TetReader finished(options_.output);  // throws unless complete
  spdlog::info("the checkpointed job had finished: {} is complete", options_.output);
  discard_padded_job(dir_);
  checkpoint_->remove();
  return true;
}

// The flags rank 0 broadcasts before each attempt's padded job.
struct Attempt {
  bool corners_full = false, images = false, skip = false, resume = false, input_as_is = false;
  std::string encode() const {
    return {char('0' + corners_full), char('0' + images), char('0' + skip), char('0' + resume),
            char('0' + input_as_is)};
  }
  static Attempt decode(const std::string& s) {
    return {s.at(0) == '1', s.at(1) == '1', s.at(2) == '1', s.at(3) == '1', s.at(4) == '1'};
  }
};
}  // namespace

void PeriodicOptions::validate() const {
  for (double l : period) {
    if (!std::isfinite(l) || !(l > 0)) throw UsageError("--periodic: every period must be a positive number");
  }
  if (!(margin_spacings > 0)) throw UsageError("--periodic-margin must be positive");
}

std::array<double, 3> parse_period(const std::string& text, const std::string& input) {
  if (text == "auto") return io::hdf5_box_size(input);
  std::vector<double> v;
  std::stringstream s(text);
  std::string item;
  while (std::getline(s, item, ',')) {
    std::size_t used = 0;
    double x = 0;
    try {
      x = std::stod(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != item.size()) throw UsageError("--periodic " + text + ": not a number: " + item);
    v.push_back(x);
  }
  if (v.size() == 1) return {v[0], v[0], v[0]};
  if (v.size() != 3) throw UsageError("--periodic " + text + ": give L, Lx,Ly,Lz or auto");
  return {v[0], v[1], v[2]};
}

namespace {
// One process: the padded job with the keep as its output stage (keep_stage.hpp), which
// writes the periodic container as the segments finish. False when a ball leaves the
// padded box (the output emptied; the margin doubles).
bool padded_job_keeping(const RunOptions& options, const PeriodicOptions& periodic, const std::string& dir, Root& job,
                        const WrappedInput& points, const Images& images, const std::array<double, 3>& margin,
                        bool resume, PeriodicSummary& sum) {
  RunOptions inner = padded_job(options, dir, points.as_is, !images.code.empty());
  inner.resume = resume;
  KeepSetup setup;
  setup.input_points = points.count;
  setup.images = &images;
  setup.period = periodic.period;
  setup.margin = margin;
  setup.input = options.input;
  setup.output = options.output;
  setup.claim = &job.claim();
  setup.frame_tets = MemoryBudget::frame_tets_for(job.header_memory());
  setup.options_json = header_options(job.header_memory(), periodic, margin);
  // The tets waiting for the frontier are a slab a few spacings thick (ties on the sort
  // axis, and the tets at the lower face that wait for the box's first points); past
  // this share the stream spills (the same bytes, through the external sort).
  setup.waiting_bytes = options.memory_bytes / 64;
  setup.sort_bytes = options.memory_bytes / 4;  // at most: after the triangulation, in what it gave back
  // The keep's tables beside the padded job's shares: that job plans within the rest.
  const std::uint64_t keep_bytes =
      keep_stage_bytes(points.count + images.code.size(), points.count, images.code.size(), setup.waiting_bytes,
                       options.threads > 0 ? options.threads : omp_get_max_threads());
  // (Not below the 32M every job takes: a budget that small holds a small input, whose
  // shares are its own needs, far below it.)
  inner.memory_bytes =
      std::max(options.memory_bytes - std::min(keep_bytes, options.memory_bytes / 4), std::uint64_t(32) << 20);
  inner.nested = true;
  inner.memory_stated = options.memory_bytes;
  inner.memory_reserved = keep_bytes;
  inner.points_stated = points.count;
  inner.frame_tets = setup.frame_tets;  // the keep's frames, in the padded job's writer share
  KeepResult kept;
  const auto make = [&](const StageContext& context, const SortedPoints&, const SortedView& view,
                        const TriangulateShares& shares,
                        const io::OutputClaim*) { return make_keep_stage(context, view, shares, setup, kept); };
  try {
    sum.padded = detail::run_job(inner, make);
  } catch (const BallsLeaveBox&) {
    sum.ball_failures = 1;
    return false;
  }
  // The padded job's partial output held its sorted points only: its tets were kept.
  remove_file(inner.output + ".partial");
  sum.points = kept.points;
  sum.tets = kept.tets;
  sum.output_bytes = kept.output_bytes;
  sum.padded.memory_ceiling = options.memory_bytes;
  auto& ledger = sum.padded.memory_shares;
  ledger.push_back(
      {"triangulate", "keep: label tables, offsets, waiting tets", std::min(keep_bytes, options.memory_bytes / 4)});
  ledger.insert(ledger.end(), kept.memory_shares.begin(), kept.memory_shares.end());
  return true;
}

// Pads, runs the padded job and keeps, doubling the margin until the certificate holds
// (docs/periodic.md). Every rank runs the padded job; rank 0 (job) all else.
void attempts(const RunOptions& options, const PeriodicOptions& periodic, Communicator& comm, const std::string& dir,
              Root* job, PeriodicSummary& sum) {
  const bool root = comm.rank() == 0;
  WrappedInput points;
  std::array<double, 3> margin{};
  together(comm, [&] {
    if (!root) return;
    const auto t = std::chrono::steady_clock::now();
    // The density counted in the same pass unless a checkpoint's margin makes it moot.
    bool recorded = false;
    if (job->checkpoint()) {
      detail::trusting_checkpoint(*job->checkpoint(), [&] {
        recorded = job->state().contains("margin");
        if (recorded) margin = job->state()["margin"].get<std::array<double, 3>>();
        sum.attempts = job->state().value("attempts", std::uint64_t(0));
      });
    }
    std::optional<std::uint64_t> density_memory;
    if (!recorded && periodic.margin_from_density) density_memory = options.memory_bytes;
    points = write_wrapped(options.input, options.read, periodic.period, periodic.wrap, dir,
                           job->checkpoint() != nullptr, density_memory);
    sum.input_points = points.count;
    sum.wrapped = points.wrapped;
    sum.input_copied = !points.as_is;
    spdlog::debug("periodic: input {} in {:.3f}s", points.as_is ? "read in place" : "wrapped into a copy",
                  seconds_since(t));
    if (!recorded) {
      margin = mean_spacing_margin(periodic, points.count);
      if (periodic.margin_from_density) {
        const auto density_start = std::chrono::steady_clock::now();
        const DensityMargin d = points.density ? std::move(*points.density).margin(margin)
                                               : margin_for_density(points.path, points.count, periodic.period, margin,
                                                                    options.memory_bytes);
        if (d.margin != margin)
          spdlog::info(
              "periodic: the first margin {:.4g} (not {:.4g}): the points near the faces are as sparse as "
              "{:.2g} of the mean",
              d.margin[0], margin[0], *std::min_element(d.sparsest.begin(), d.sparsest.end()));
        margin = d.margin;
        spdlog::debug("periodic: the density's margin in {:.3f}s{}", seconds_since(density_start),
                      points.density ? " (its counts taken in the input's pass)" : "");
      }
    }
    sum.seconds_pad += seconds_since(t);
  });
  for (;;) {
    Attempt a;
    Images images;
    together(comm, [&] {
      if (!root) return;
      const auto t = std::chrono::steady_clock::now();
      ++sum.attempts;
      images = write_images(points, periodic.period, margin, dir, job->checkpoint() != nullptr);
      sum.images = images.code.size();
      spdlog::debug("periodic: {} images in {:.3f}s", sum.images, seconds_since(t));
      // The padded job's work in the checkpoint: its nested checkpoint resumes, its
      // output (recorded with its fingerprint once complete) is kept; any other is redone.
      json& state = job->state();
      const std::string padded = dir + "/" + kPadded;
      const bool nested = exists(padded + ".ckpt");
      if (points.rewritten || images.rewritten) {
        state.erase("padded");
        discard_padded_job(dir);  // stale: made from other padded points
      } else if (!state.contains("padded") ||
                 state["padded"].value("fingerprint", json()) != fingerprint_if_there(padded)) {
        state.erase("padded");
        if (!nested) remove_file(padded);  // complete but not recorded (or damaged): made again
      }
      state["margin"] = margin;
      state["attempts"] = sum.attempts;
      job->save();
      a.corners_full = images.corners_full;
      a.images = !images.code.empty();
      a.input_as_is = points.as_is;
      a.skip = state.contains("padded");
      a.resume = exists(dir + "/" + kPadded + ".ckpt");
      sum.seconds_pad += seconds_since(t);
    });
    a = Attempt::decode(comm.broadcast(root ? a.encode() : "", 0));
    bool complete = false;
    if (a.corners_full && comm.size() == 1) {
      complete = padded_job_keeping(options, periodic, dir, *job, points, images, margin, a.resume, sum);
      if (complete) {
        sum.margin = margin;
        // The keep's own time on the job's thread (its tables, the segments' hand-over,
        // the end); its certificate ran in the zones, on their threads.
        sum.seconds_keep = sum.padded.seconds_write;
        job->state()["done"] = done_record(sum);
      } else {
        spdlog::info("periodic: a ball leaves the padded box at margin {:.4g}: doubling it", margin[0]);
        discard_padded_job(dir);
      }
      job->save();
    } else if (a.corners_full) {
      RunOptions inner = padded_job(options, dir, a.input_as_is, a.images);
      inner.resume = a.resume;
      if (!a.skip) {
        sum.padded = comm.size() > 1 ? run_job_distributed(inner, comm) : run_job(inner);
        together(comm, [&] {
          if (!root) return;
          job->state()["padded"] = {{"axis", sum.padded.axis}, {"fingerprint", fingerprint_file(inner.output)}};
          job->save();
        });
      }
      together(comm, [&] {
        if (!root) return;
        const auto t = std::chrono::steady_clock::now();
        if (a.skip) {  // the padded job had finished before a kill: only the keep step again
          spdlog::info("resuming the periodic job in {}: its padded job had finished", dir);
          sum.resumed = true;
          detail::trusting_checkpoint(*job->checkpoint(),
                                      [&] { sum.padded.axis = job->state().at("padded").at("axis").get<int>(); });
        }
        KeepInput in;
        in.padded = inner.output;
        in.input_points = points.count;
        in.images = &images;
        in.period = periodic.period;
        in.margin = margin;
        in.sort_axis = sum.padded.axis;
        in.input = options.input;
        in.output = options.output;
        in.claim = &job->claim();
        in.dir = dir;
        in.memory_bytes = options.memory_bytes;
        in.frame_tets = MemoryBudget::frame_tets_for(job->header_memory());
        in.threads = options.threads > 0 ? options.threads : int(std::max(1u, std::thread::hardware_concurrency()));
        in.options_json = header_options(job->header_memory(), periodic, margin);
        const KeepResult kept = keep_periodic_tets(in);
        sum.ball_failures = kept.ball_failures;
        complete = kept.complete;
        if (complete) {
          sum.points = kept.points;
          sum.tets = kept.tets;
          sum.output_bytes = kept.output_bytes;
          sum.margin = margin;
          auto& ledger = sum.padded.memory_shares;
          ledger.insert(ledger.end(), kept.memory_shares.begin(), kept.memory_shares.end());
          job->state()["done"] = done_record(sum);
        } else {
          spdlog::info("periodic: {} balls leave the padded box at margin {:.4g}: doubling it", kept.ball_failures,
                       margin[0]);
          job->state().erase("padded");
        }
        job->save();  // before the padded output it no longer names goes
        remove_file(inner.output);
        sum.seconds_keep += seconds_since(t);
      });
    } else if (root) {
      spdlog::info("periodic: a corner of the padded box is empty at margin {:.4g}: doubling it", margin[0]);
    }
    if (comm.broadcast(complete ? "1" : "", 0) == "1") break;
    together(comm, [&] {
      if (!root) return;
      if (margin[0] >= periodic.period[0] && margin[1] >= periodic.period[1] && margin[2] >= periodic.period[2]) {
        throw InputError(options.input + ": the periodic Delaunay triangulation of these " +
                         std::to_string(points.count) +
                         " points is not certified in the 1-sheeted covering (an empty ball reaches across a whole "
                         "period): too few points for the box (docs/periodic.md, \"When it refuses\")");
      }
      for (int k = 0; k < 3; ++k) margin[k] = std::min(2 * margin[k], periodic.period[k]);
    });
  }
  if (job && job->checkpoint()) {
    discard_padded_job(dir);
    job->checkpoint()->remove();
  }
}
}  // namespace

PeriodicSummary run_periodic(const RunOptions& requested, const PeriodicOptions& periodic, Communicator& comm) {
  const auto start = std::chrono::steady_clock::now();
  const bool root = comm.rank() == 0;
  RunOptions options;
  // The same checks on every rank (the same options): the same answer everywhere.
  together(comm, [&] {
    periodic.validate();
    options = detail::capped_options(requested);
    if (io::is_std_stream(options.input) || io::is_std_stream(options.output))
      throw UsageError("--periodic needs an input file and an output file (not standard input or output)");
  });
  PeriodicSummary sum;
  std::optional<Root> job;
  bool finished = false;
  together(comm, [&] {
    if (!root) return;
    job.emplace(options, periodic, comm.size());
    finished = job->open(sum);
  });
  if (comm.broadcast(finished ? "1" : "", 0) == "1") {
    sum.resumed = true;
    sum.seconds_total = seconds_since(start);
    return sum;
  }
  const std::string dir = comm.broadcast(root ? job->dir() : "", 0);
  try {
    attempts(options, periodic, comm, dir, job ? &*job : nullptr, sum);
  } catch (...) {
    if (!root || !job->checkpoint()) throw;
    try {
      throw;
    } catch (const DamagedCheckpoint&) {
    } catch (const InputError&) {
      discard_padded_job(dir);  // nothing to resume: the nested checkpoint goes with the job's
    } catch (...) {
    }
    detail::rethrow_job_failure(*job->checkpoint(), options);
  }
  sum.seconds_total = seconds_since(start);
  return sum;
}

nlohmann::json periodic_summary_json(const RunOptions& options, const PeriodicOptions& periodic,
                                     const PeriodicSummary& s) {
  nlohmann::json j = run_summary_json(options, s.padded);
  j["periodic"] = {{"period", periodic.period},
                   {"margin", s.margin},
                   {"points", s.points},
                   {"input_points", s.input_points},
                   {"wrapped", s.wrapped},
                   {"input_copied", s.input_copied},
                   {"images", s.images},
                   {"tets", s.tets},
                   {"attempts", s.attempts},
                   {"seconds_pad", s.seconds_pad},
                   {"seconds_keep", s.seconds_keep},
                   {"seconds_total", s.seconds_total},
                   {"resumed", s.resumed},
                   {"output_bytes", s.output_bytes}};
  return j;
}

}  // namespace tetstream::pipeline::periodic
