#include "pipeline/run.hpp"

#include "pipeline/frame_cutter.hpp"
#include "pipeline/memory_budget.hpp"
#include "pipeline/zone_plan.hpp"

#include "core/error.hpp"
#include "io/output_file.hpp"
#include "io/point_format.hpp"
#include "io/point_reader.hpp"
#include "io/tet_container.hpp"
#include "io/tet_reader.hpp"
#include "io/tet_writer.hpp"
#include "pipeline/async_tet_writer.hpp"
#include "pipeline/checkpoint.hpp"
#include "pipeline/disk_plan.hpp"
#include "pipeline/fault.hpp"
#include "pipeline/hull.hpp"
#include "pipeline/interrupt.hpp"
#include "pipeline/point_sort.hpp"
#include "pipeline/progress.hpp"
#include "pipeline/segment.hpp"
#include "pipeline/temp_files.hpp"

#include <boost/iostreams/device/mapped_file.hpp>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <atomic>
#include <exception>
#include <optional>
#include <malloc.h>
#include <unistd.h>
#include <omp.h>

namespace tetstream::pipeline {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

}  // namespace

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
  if (unit.size() == 3 && unit.substr(1) == "IB") unit = unit.substr(0, 1);  // KiB, MiB, ...
  else if (unit.size() == 2 && unit[1] == 'B') unit = unit.substr(0, 1);     // KB, MB, ...
  double scale = 0;
  if (unit == "" || unit == "B") scale = 1;
  else if (unit == "K") scale = 1024.0;
  else if (unit == "M") scale = 1024.0 * 1024;
  else if (unit == "G") scale = 1024.0 * 1024 * 1024;
  else if (unit == "T") scale = 1024.0 * 1024 * 1024 * 1024;
  else throw UsageError("bad memory size '" + text + "': unknown unit '" + text.substr(used) + "' (use K, M, G, T)");
  if (!(value > 0) || !std::isfinite(value) || value * scale >= 0x1p63)
    throw UsageError("bad memory size '" + text + "': must be positive and below 8 EiB");
  return std::uint64_t(value * scale);
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

json bbox_json(const double* v) { return json::array({v[0], v[1], v[2]}); }
void bbox_from(const json& j, double* v) {
  for (int k = 0; k < 3; ++k) v[k] = j.at(k).get<double>();
}
std::string base_name(const std::string& path) { return std::filesystem::path(path).filename().string(); }

json to_json(const SortProgress& p) {
  json runs = json::array();
  for (const SortRunFile& r : p.runs)
    runs.push_back({{"file", base_name(r.path)}, {"records", r.records}, {"crc32c", r.crc32c},
                    {"hull_file", base_name(r.hull_path)}, {"hull_count", r.hull_count}, {"hull_crc32c", r.hull_crc32c}});
  return {{"scanned", p.scanned}, {"input_count", p.input_count}, {"bbox_min", bbox_json(p.bbox_min)},
          {"bbox_max", bbox_json(p.bbox_max)}, {"axis", p.axis}, {"runs", runs}};
}
// The sort's progress as the checkpoint recorded it, less the runs from the first one
// whose files are missing or fail their checksums: the sort redoes those from the
// input (a damaged piece is recomputed, not trusted).
SortProgress sort_progress_from(const json& j, const Checkpoint& ckpt) {
  SortProgress p;
  p.scanned = j.at("scanned").get<bool>();
  p.input_count = j.at("input_count").get<std::uint64_t>();
  bbox_from(j.at("bbox_min"), p.bbox_min);
  bbox_from(j.at("bbox_max"), p.bbox_max);
  p.axis = j.at("axis").get<int>();
  for (const json& r : j.at("runs")) {
    SortRunFile run{ckpt.path(r.at("file").get<std::string>()), r.at("records").get<std::uint64_t>(),
                    ckpt.path(r.at("hull_file").get<std::string>()), r.at("hull_count").get<std::uint64_t>(),
                    r.at("crc32c").get<std::uint32_t>(), r.at("hull_crc32c").get<std::uint32_t>()};
    if (!file_matches(run.path, run.records * sizeof(SortedPoint), run.crc32c) ||
        !file_matches(run.hull_path, run.hull_count * sizeof(std::uint64_t), run.hull_crc32c)) {
      spdlog::warn("{}: damaged or missing (size or checksum): sorting again from run {}", run.path, p.runs.size());
      break;
    }
    p.runs.push_back(run);
  }
  return p;
}

constexpr const char* kHullFile = "hull.labels";

json to_json(const SortedPoints& s) {
  return {{"file", base_name(s.path)}, {"count", s.count},       {"input_count", s.input_count},
          {"duplicates", s.duplicates}, {"axis", s.axis},        {"bbox_min", bbox_json(s.bbox_min)},
          {"bbox_max", bbox_json(s.bbox_max)}, {"runs", s.runs}, {"hull_count", s.hull_labels.size()},
          {"crc32c", s.crc32c}, {"hull_crc32c", io::crc32c(s.hull_labels.data(), s.hull_labels.size() * sizeof(std::uint64_t))}};
}
// The sorted file and the hull's labels as the checkpoint recorded them; nullopt when
// either is missing or fails its checksum (the job sorts again, and must then come to
// the same bytes: see Job::sort).
std::optional<SortedPoints> sorted_from(const json& j, const Checkpoint& ckpt) {
  SortedPoints s;
  s.path = ckpt.path(j.at("file").get<std::string>());
  s.count = j.at("count").get<std::uint64_t>();
  s.input_count = j.at("input_count").get<std::uint64_t>();
  s.duplicates = j.at("duplicates").get<std::uint64_t>();
  s.axis = j.at("axis").get<int>();
  bbox_from(j.at("bbox_min"), s.bbox_min);
  bbox_from(j.at("bbox_max"), s.bbox_max);
  s.runs = j.at("runs").get<std::size_t>();
  s.crc32c = j.at("crc32c").get<std::uint32_t>();
  s.hull_labels.resize(j.at("hull_count").get<std::size_t>());
  try {
    read_file_exactly(ckpt.path(kHullFile), s.hull_labels.data(), s.hull_labels.size() * sizeof(std::uint64_t),
                      j.at("hull_crc32c").get<std::uint32_t>());
  } catch (const DamagedCheckpoint& e) {
    spdlog::warn("{}: sorting again", e.what());
    return std::nullopt;
  }
  if (!file_matches(s.path, s.count * sizeof(SortedPoint), s.crc32c)) {
    spdlog::warn("{}: damaged or missing (size or checksum): sorting again", s.path);
    return std::nullopt;
  }
  return s;
}

// The work of the segments written so far, carried across a resume so that the
// final summary describes the whole job.
json counters_json(const SegmentStats& w, std::uint64_t zone_points) {
  return {{"zone_points", zone_points}, {"window_points", w.window_points}, {"repair_points", w.repair_points},
          {"segment_buffer_points", w.segment_buffer_points}, {"zone_buffer_points", w.zone_buffer_points},
          {"hull_points", w.hull_points},
          {"range_failures", w.range_failures}, {"queries", w.queries}, {"query_points", w.query_points},
          {"rounds", w.rounds}, {"tets", w.tets}, {"seconds_build", w.seconds_build}, {"seconds_check", w.seconds_check}};
}
void counters_from(const json& j, SegmentStats& w, std::uint64_t& zone_points) {
  zone_points = j.at("zone_points").get<std::uint64_t>();
  w.window_points = j.at("window_points").get<std::uint64_t>();
  w.repair_points = j.at("repair_points").get<std::uint64_t>();
  w.segment_buffer_points = j.at("segment_buffer_points").get<std::uint64_t>();
  w.zone_buffer_points = j.at("zone_buffer_points").get<std::uint64_t>();
  w.hull_points = j.at("hull_points").get<std::uint64_t>();
  w.range_failures = j.at("range_failures").get<std::uint64_t>();
  w.queries = j.at("queries").get<std::uint64_t>();
  w.query_points = j.at("query_points").get<std::uint64_t>();
  w.rounds = j.at("rounds").get<std::uint64_t>();
  w.tets = j.at("tets").get<std::uint64_t>();
  w.seconds_build = j.at("seconds_build").get<double>();
  w.seconds_check = j.at("seconds_check").get<double>();
}
void record_work(const SegmentStats& w, std::uint64_t zone_points, RunSummary& s) {
  s.zone_points = zone_points;
  s.window_points = w.window_points;
  s.repair_points = w.repair_points;
  s.segment_buffer_points = w.segment_buffer_points;
  s.zone_buffer_points = w.zone_buffer_points;
  s.hull_window_points = w.hull_points;
  s.range_failures = w.range_failures;
  s.queries = w.queries;
  s.query_points = w.query_points;
  s.seconds_build = w.seconds_build;
  s.seconds_check = w.seconds_check;
  s.rounds_max = w.rounds;
  s.tets = w.tets;
  s.seconds_segments = w.seconds_build + w.seconds_check;
}

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
          {"read", o.read.identity()}};
}

// One line naming what differs between a checkpoint's job and this one.
std::string identity_difference(const json& saved, const json& now) {
  if (saved.at("input") != now.at("input"))
    return "the input was " + saved.at("input").get<std::string>() + ", now " + now.at("input").get<std::string>();
  if (saved.at("input_fingerprint") != now.at("input_fingerprint"))
    return "the input " + now.at("input").get<std::string>() + " changed (size, time or contents) since the checkpoint";
  // Not "memory": a resumed job may take another budget (the frames do not depend on
  // it, and the header keeps the budget it was written with; see Job::run).
  for (const char* key : {"output", "buffer_spacings", "sort_run_points", "read"})
    if (saved.at(key) != now.at(key)) return std::string("option '") + key + "' was " + saved.at(key).dump() + ", now " + now.at(key).dump();
  return "";
}

class Job {
 public:
  Job(const RunOptions& options, std::string dir, Checkpoint* checkpoint, json state, const io::OutputClaim* claim)
      : options_(options),
        dir_(std::move(dir)),
        checkpoint_(checkpoint),
        state_(std::move(state)),
        claim_(claim),
        threads_(options.threads > 0 ? options.threads : omp_get_max_threads()),
        budget_(options.memory_bytes, 0, threads_, omp_get_num_procs()) {}
  RunSummary run();

 private:
  SortedPoints sort();
  void index_and_hull(const SortedPoints& sorted, const boost::iostreams::mapped_file_source& mapping,
                      SortedView& view, PointIndex& index, PointIndex& hull_index);
  struct OpenedOutput {
    std::unique_ptr<io::TetWriter> writer;
    SegmentStats work;             // of the segments an earlier process wrote
    std::uint64_t zone_points = 0;
    std::uint64_t first_label = 0;  // where the segments go on
    std::vector<std::uint64_t> pending;  // the frame that was being filled (4 labels a tet)
  };
  OpenedOutput open_output(const SortedPoints& sorted, const SortedView& view, const TriangulateShares& shares);
  void save() {
    if (checkpoint_) checkpoint_->save(state_);
  }

  const RunOptions& options_;
  std::string dir_;
  Checkpoint* checkpoint_;  // null: not resumable
  json state_;              // what the checkpoint holds (maintained even without one)
  const io::OutputClaim* claim_;  // the output, locked for this job since it began
  const int threads_;             // the zones triangulated at once
  MemoryBudget budget_;           // the ledger: every stage's share of --memory
  RunSummary summary_;
  Clock::time_point start_ = Clock::now();
};

// Stage 1, or what a checkpoint kept of it. A sorted file that fails its checksum is
// made again; the new one must have the recorded checksum (the labels that the
// output written so far uses), else the checkpoint is refused as damaged.
SortedPoints Job::sort() {
  std::optional<std::uint32_t> expected_crc;
  if (state_.contains("sorted")) {
    if (std::optional<SortedPoints> kept = sorted_from(state_["sorted"], *checkpoint_)) return *kept;
    // "sorted" stays in the state until the new file replaces it: a crash while
    // sorting again still finds the checksum to come to.
    expected_crc = state_["sorted"].at("crc32c").get<std::uint32_t>();
  }
  PointSortOptions sort_options;
  sort_options.memory_bytes = std::size_t(options_.memory_bytes);
  sort_options.budget = &budget_;
  sort_options.run_points = std::size_t(options_.sort_run_points);
  // Before any run is written: a budget that cannot hold even the thinnest windows
  // of this many points is refused now, not after the sort.
  sort_options.on_scanned = [this](const SortProgress& p) { refuse_budget_before_sort(p, options_, threads_); };
  sort_options.progress = options_.progress;
  SortProgress progress;
  if (checkpoint_) {
    if (state_.contains("sort")) progress = sort_progress_from(state_["sort"], *checkpoint_);
    sort_options.resume = &progress;
    sort_options.on_step = [this](const SortProgress& p) {
      state_["sort"] = to_json(p);
      save();
    };
  }
  SortedPoints sorted = sort_points(options_.input, options_.read, sort_options, dir_);
  if (expected_crc && sorted.crc32c != *expected_crc)
    throw DamagedCheckpoint(sorted.path + ": sorted again after a checksum failure, the points differ from the "
                            "checkpoint's (damaged checkpoint, or the input changed)");
  if (checkpoint_) {
    write_file_atomically(dir_, kHullFile, sorted.hull_labels.data(), sorted.hull_labels.size() * sizeof(std::uint64_t));
    state_["sorted"] = to_json(sorted);
    state_.erase("sort");
    save();
    // The runs are merged into the sorted file, and the state no longer names them.
    for (const SortRunFile& r : progress.runs) remove_file(r.path), remove_file(r.hull_path);
  }
  return sorted;
}

// Stage 2: the spatial index over the sorted file, and the global hull's boundary
// points (the hull of the runs' candidates) with their own small index.
void Job::index_and_hull(const SortedPoints& sorted, const boost::iostreams::mapped_file_source& mapping,
                         SortedView& view, PointIndex& index, PointIndex& hull_index) {
  view.sample_keys(/*release_file_pages=*/true);
  // An index over sorted records spread in the job's bounding box (its blocks' size
  // from their count in that box).
  auto build_index = [&view](PointIndex& into, const SortedPoint* points, std::uint64_t count, bool release_pages) {
    double volume = 1;
    for (int k = 0; k < 3; ++k) volume *= view.bbox_max[k] - view.bbox_min[k];
    into.build(points, count, view.axis,
                PointIndex::block_points_for(count, view.bbox_max[view.axis] - view.bbox_min[view.axis], volume),
                release_pages);
  };
  build_index(index, view.points, view.count, /*release_pages=*/true);
  view.index = &index;

  // The global hull: the hull of the runs' candidates.
  {
    std::vector<double> xyz;
    // In label order, handing the pages back behind: a shell's hull candidates are
    // all over the file.
    ReleaseBehind release(view.points, 0, true);
    for (std::uint64_t label : sorted.hull_labels) {
      xyz.insert(xyz.end(), view.points[label].xyz, view.points[label].xyz + 3);
      release.reached(label);
    }
    std::vector<std::uint32_t> hull = hull_vertex_candidates(xyz.data(), sorted.hull_labels.size());
    std::sort(hull.begin(), hull.end());  // candidates are sorted by label: so are these
    for (std::uint32_t i : hull) {
      SortedPoint p;
      std::copy_n(&xyz[3 * std::size_t(i)], 3, p.xyz);
      p.original = sorted.hull_labels[i];
      view.hull_points.push_back(p);
    }
    release_mapped_pages(mapping.data(), mapping.size());
    summary_.hull_vertices = view.hull_points.size();
  }
  if (!view.hull_points.empty()) build_index(hull_index, view.hull_points.data(), view.hull_points.size(), false);
  view.hull_index = &hull_index;
}

// Stage 5's file: the container's header and writer, new, or the checkpoint's partial
// output reopened at its last commit with the frame pending there and the counters.
Job::OpenedOutput Job::open_output(const SortedPoints& sorted, const SortedView& view, const TriangulateShares& shares) {
  // The budget the output's header names: the one its first process wrote it with (a
  // resumed job may run with another; the frames do not depend on it).
  if (!state_.contains("header_memory")) state_["header_memory"] = options_.memory_bytes;
  const std::uint64_t header_memory = state_["header_memory"].get<std::uint64_t>();
  if (header_memory != options_.memory_bytes)
    spdlog::info("resumed with --memory {}: the output keeps the budget it was started with, {}",
                 human_bytes(double(options_.memory_bytes)), human_bytes(double(header_memory)));
  io::TetFileHeader header;
  header.point_count = view.count;
  header.input_count = sorted.input_count;
  header.coord_type = io::CoordType::kFloat64;
  for (int k = 0; k < 3; ++k) header.bbox_min[k] = view.bbox_min[k], header.bbox_max[k] = view.bbox_max[k];
  header.tool = "tetstream 0.1.0";
  header.options = json{{"command", "run"},
                        {"input", options_.input},
                        {"memory", header_memory},
                        {"buffer_spacings", options_.buffer_spacings},
                        {"axis", std::string(1, "xyz"[view.axis])},
                        {"duplicates_merged", sorted.duplicates}}
                       .dump();
  io::TetWriterOptions writer_options;
  writer_options.threads = shares.encoders;  // the writer stage's own team
  // Frames are cut here (FrameCutter), not by the writer: a batch is one frame.
  writer_options.frame_tets = 2 * kFrameTets;
  writer_options.keep_partial = checkpoint_ != nullptr;
  writer_options.claim = claim_;
  OpenedOutput o;
  if (state_.contains("output")) {
    const json& out = state_["output"];
    const std::uint64_t committed = out.at("committed").get<std::uint64_t>();
    std::error_code ec;
    const std::string partial = options_.output + ".partial";
    const std::uintmax_t have = std::filesystem::file_size(partial, ec);
    if (ec || have < committed)
      throw DamagedCheckpoint(partial + ": " + (ec ? std::string("missing") : std::to_string(have) + " bytes") +
                              ", but the checkpoint committed " + std::to_string(committed) + " (damaged checkpoint)");
    try {
      o.writer = io::TetWriter::resume(options_.output, header, committed, writer_options);
    } catch (const InputError& e) {
      throw DamagedCheckpoint(std::string(e.what()) + " (damaged checkpoint)");
    }
    o.first_label = out.at("next_label").get<std::uint64_t>();
    o.pending.resize(4 * out.at("pending_tets").get<std::size_t>());
    if (!o.pending.empty())
      read_file_exactly(checkpoint_->path(out.at("pending_file").get<std::string>()), o.pending.data(),
                        o.pending.size() * sizeof(std::uint64_t), out.at("pending_crc32c").get<std::uint32_t>());
    counters_from(out.at("counters"), o.work, o.zone_points);
    record_work(o.work, o.zone_points, summary_);
    summary_.segments_resumed = out.at("segments").get<std::uint64_t>();
    spdlog::info("resuming after {} segments: labels from {} of {}, {} tets written", summary_.segments_resumed,
                 o.first_label, view.count, summary_.tets);
  } else {
    o.writer = std::make_unique<io::TetWriter>(options_.output, header, writer_options);
  }
  return o;
}

RunSummary Job::run() {
  RunSummary& summary = summary_;
  summary.resumed = state_.contains("sort") || state_.contains("sorted");

  // ---- stage 1: external sort ----
  SortedPoints sorted = sort();
  summary.input_points = sorted.input_count;
  summary.points = sorted.count;
  summary.duplicates = sorted.duplicates;
  summary.axis = sorted.axis;
  summary.seconds_sort = since(start_);
  spdlog::info("sorted {} points ({} duplicates merged) along {} in {} runs, {:.1f}s", sorted.count,
               sorted.duplicates, "xyz"[sorted.axis], sorted.runs, summary.seconds_sort);
  if (sorted.count < 4) throw InputError(options_.input + ": fewer than 4 distinct points");

  boost::iostreams::mapped_file_source mapping;
  try {
    mapping.open(sorted.path);
  } catch (const std::exception& e) {
    throw IoError(sorted.path + ": cannot map: " + e.what());
  }
  SortedView view;
  view.points = reinterpret_cast<const SortedPoint*>(mapping.data());
  view.count = sorted.count;
  view.axis = sorted.axis;
  for (int k = 0; k < 3; ++k) view.bbox_min[k] = sorted.bbox_min[k], view.bbox_max[k] = sorted.bbox_max[k];

  PointIndex index, hull_index;
  index_and_hull(sorted, mapping, view, index, hull_index);

  // ---- segment plan from the budget ----
  const int threads = threads_;
  const PlanInputs inputs = plan_inputs(view, index);
  const ZonePlan zone_plan = plan_for_budget(inputs, options_, threads);
  budget_.set_points(view.count);
  const TriangulateShares shares = budget_.plan_triangulate(inputs.index_bytes, zone_plan.window_bytes);
  for (const MemoryBudget::Share& share : budget_.shares())
    spdlog::debug("memory: {} {} {}", share.phase, share.name, human_bytes(double(share.bytes)));
  // An eighth of the budget, shared by the workers, for the pages of the sorted file
  // their queries read, counted in the 2 MiB regions that a read may map
  // (MappedRegions). The queries of a zone read the file along the sort axis, and a
  // share that holds their sweep saves faulting regions in again. Measured before
  // scattered reads bypassed the mapping, on 10^7 points: uniform at 256M took 77 s
  // with a twentieth of the budget, 61 s with a tenth, 56 s with an eighth (53 s before
  // the regions were counted, peaking over the budget); mixed at 512M 60 s with a
  // tenth, 50 s with an eighth, 41 s with a fifth (49 s before, over the budget).
  MappedRegions query_regions(mapping.data(), mapping.size(),
                              std::max<std::size_t>(1, std::size_t(shares.query_page_bytes / MappedRegions::kRegionBytes)),
                              sorted.path);
  view.query_regions = &query_regions;
  const double buffer_width = zone_plan.buffer_width;

  // ---- writer: header and points (or the checkpoint's partial output) ----
  OpenedOutput opened = open_output(sorted, view, shares);
  std::unique_ptr<io::TetWriter> writer_holder = std::move(opened.writer);
  SegmentStats work = opened.work;  // of the segments written, this process's and earlier ones'
  std::uint64_t zone_points_done = opened.zone_points;
  const std::uint64_t first_label = opened.first_label;
  std::vector<std::uint64_t> pending = std::move(opened.pending);
  // Stage 5 on its own thread behind a bounded queue of frames: compression and I/O
  // overlap the segments. Declared after the writer, so destroyed (cancelled, joined)
  // before it on the way out of a failure.
  const std::size_t encoders = std::size_t(shares.encoders);
  AsyncTetWriter writer(*writer_holder, encoders, encoders);
  if (!state_.contains("output")) {
    // The points section, in label order, on the writer's thread while the first
    // zones are triangulated (a pass over the whole sorted file, which used to hold
    // the first segment back).
    writer.add_task([&view](io::TetWriter& w) {
      constexpr std::size_t kChunk = 1 << 16;
      std::vector<double> xyz(3 * kChunk);
      std::vector<std::uint64_t> ids(kChunk);
      for (std::uint64_t first = 0; first < view.count; first += kChunk) {
        const std::size_t n = std::size_t(std::min<std::uint64_t>(kChunk, view.count - first));
        for (std::size_t i = 0; i < n; ++i) {
          const SortedPoint& p = view.points[first + i];
          xyz[3 * i] = p.xyz[0], xyz[3 * i + 1] = p.xyz[1], xyz[3 * i + 2] = p.xyz[2];
          ids[i] = p.original;
        }
        w.add_points(xyz.data(), ids.data(), n);
        release_mapped_pages(view.points + first, n * sizeof(SortedPoint));
        check_interrupted();
      }
    });
  }
  FrameCutter cutter(writer);
  cutter.restore(std::move(pending));
  std::uint64_t segments_done = summary.segments_resumed;
  // Records that the output holds every tet of the labels below `next_label`: the
  // writer's committed bytes, the tets of the frame being filled, the counters. The
  // frame being filled is saved at once (under a name of its own); the state that
  // names it is saved by the writer's thread once the frames before it are on disk,
  // so the segments never wait for the writer. A crash in between leaves the previous
  // state, which names the previous pending file: that one is removed only after.
  // `wait`: return only when the state is saved (the job's last commit).
  auto commit = [&](std::uint64_t next_label, bool wait) {
    if (!checkpoint_) return;
    const std::string pending_file = "pending-" + std::to_string(segments_done) + ".tets";
    const auto& p = cutter.pending();
    if (!p.empty()) write_file_atomically(dir_, pending_file, p.data(), p.size() * sizeof(std::uint64_t));
    const std::string old_pending = state_.contains("output") ? state_["output"].value("pending_file", "") : "";
    state_["output"] = {{"committed", 0},
                        {"next_label", next_label},
                        {"pending_file", pending_file},
                        {"pending_tets", p.size() / 4},
                        {"pending_crc32c", io::crc32c(p.data(), p.size() * sizeof(std::uint64_t))},
                        {"segments", segments_done},
                        {"counters", counters_json(work, zone_points_done)}};
    const std::string old_path = old_pending.empty() || old_pending == pending_file ? "" : checkpoint_->path(old_pending);
    auto persist = [this, old_path](json state, std::uint64_t committed) {
      state["output"]["committed"] = committed;
      checkpoint_->save(std::move(state));
      if (!old_path.empty()) remove_file(old_path);
    };
    if (wait) {
      state_["output"]["committed"] = writer.checkpoint();  // drains first
      persist(state_, state_["output"]["committed"].get<std::uint64_t>());
    } else {
      writer.add_checkpoint([persist, state = state_](std::uint64_t committed) { persist(state, committed); });
    }
  };
  if (!state_.contains("output")) commit(0, false);

  auto plans = plan_segments(view, zone_plan.segment_points, buffer_width, first_label);
  struct Unit {
    std::size_t segment;
    std::size_t zone;
  };
  std::vector<Unit> units;
  for (std::size_t s = 0; s < plans.size(); ++s) {
    split_into_zones(view, plans[s], zone_plan.zones);
    for (std::size_t z = 0; z < plans[s].zones.size(); ++z) units.push_back({s, z});
    // The samples touch about every page of the segment's labels: hand them back
    // now, or the whole mapped file would be resident before the first zone starts.
    release_mapped_pages(view.points + plans[s].zone_begin,
                         (plans[s].zone_end - plans[s].zone_begin) * sizeof(SortedPoint));
  }
  summary.segments = segments_done + plans.size();
  summary.zones = units.size();
  spdlog::info("{} segments of ~{} points in {} zones of ~{} points, buffer {:.3g} ({} spacings), {} hull vertices",
               plans.size(), plans.empty() ? 0 : plans[0].zone_end - plans[0].zone_begin, units.size(),
               plans.empty() ? 0 : (plans[0].zone_end - plans[0].zone_begin) / plans[0].zones.size(), buffer_width,
               options_.buffer_spacings, view.hull_points.size());

  // ---- stages 2-5: zones, `threads` at a time, written in segment order ----
  // Each thread triangulates whole zones (they are independent given the sorted
  // file). The ordered region collects a segment's zones in plan order; after its
  // last one it merges them by minimum label into the writer's frames, so the bytes
  // depend neither on the thread count nor on the plan. A finished zone waits there
  // for its predecessors: at most `threads` zones are in flight, and the outputs of
  // at most one segment plus `threads` - 1 zones are held, which is what the plan
  // above was sized for. After each segment the checkpoint records the output so
  // far: a crash loses the zones finished or started since.
  Progress progress("triangulating", "points", view.count, options_.progress);
  progress.add(first_label);
  std::exception_ptr failure;
  std::atomic<bool> cancelled{false};
  const auto stage_start = Clock::now();
  const std::int64_t unit_count = std::int64_t(units.size());
  const std::uint64_t first_segment = segments_done;  // segments_done changes in the loop
  std::vector<ZoneTets> parts;                        // the current segment's zones' tets
  SegmentStats segment_work;
  // Per thread, a triangulator whose buffers live from zone to zone; and the zones'
  // output vectors, recycled once merged. Fresh memory for each zone cost the OS's
  // page zeroing, 10.5% of a one-thread profile.
  OutputPool output_pool;
  std::vector<std::unique_ptr<ZoneTriangulator>> triangulators(static_cast<std::size_t>(threads));
#pragma omp parallel for ordered schedule(dynamic, 1) num_threads(threads)
  for (std::int64_t i = 0; i < unit_count; ++i) {
    const Unit unit = units[std::size_t(i)];
    const SegmentPlan& plan = plans[unit.segment];
    ZoneTets tets;
    SegmentStats s;
    if (!cancelled.load()) {
      try {
        check_interrupted();
        maybe_inject_fault("segment", first_segment + unit.segment);
        auto& triangulator = triangulators[std::size_t(omp_get_thread_num())];
        if (!triangulator) triangulator = std::make_unique<ZoneTriangulator>(view, &output_pool);
        s = triangulator->run(plan, plan.zones[unit.zone], tets);
      } catch (...) {
        // A worker never throws out of the parallel region (that would terminate the
        // process): the first failure is kept, the others stop, and it is rethrown
        // after the join.
#pragma omp critical(tetstream_run_failure)
        if (!failure) failure = std::current_exception();
        cancelled = true;
      }
    }
#pragma omp ordered
    {
      if (!cancelled.load()) {
        parts.push_back(std::move(tets));
        segment_work += s;
        const std::uint64_t points = plan.zone_end - plan.zone_begin, k = plan.zones.size();
        progress.add(points * (unit.zone + 1) / k - points * unit.zone / k);
        if (unit.zone + 1 == plan.zones.size()) {
          try {
            const auto t0 = Clock::now();
            maybe_inject_fault("write", segments_done);
            merge_by_min_label(parts, [&](const ZoneTets& part, std::size_t b, std::size_t e) { cutter.add(part, b, e); });
            work += segment_work;
            zone_points_done += points;
            record_work(work, zone_points_done, summary);
            ++segments_done;
            commit(plan.zone_end, false);
            summary.seconds_write += since(t0);
          } catch (...) {
#pragma omp critical(tetstream_run_failure)
            if (!failure) failure = std::current_exception();
            cancelled = true;
          }
          spdlog::debug("segment [{}, {}) in {} zones: windows {} (+{} repairs), {} range failures, {} queries, "
                        "{} rounds, {} tets, build {:.2f}s check {:.2f}s (summed), kernels {}",
                        plan.zone_begin, plan.zone_end, k, segment_work.window_points, segment_work.repair_points,
                        segment_work.range_failures, segment_work.queries, segment_work.rounds, segment_work.tets,
                        segment_work.seconds_build, segment_work.seconds_check,
                        human_bytes(double(segment_work.kernel_bytes)));
          for (auto& part : parts) output_pool.give(std::move(part));
          parts.clear();
          segment_work = SegmentStats{};
        }
      }
      tets = ZoneTets{};
      release_mapped_pages(mapping.data(), mapping.size());
      malloc_trim(0);  // hand any freed heap back, so resident memory tracks the windows
    }
  }
  if (failure) {
    try {
      std::rethrow_exception(failure);
    } catch (const DamagedCheckpoint&) {
      throw;
    } catch (const InputError& e) {
      // The kernel's word on the points (too few affinely independent ones) names no
      // file: the input is the job's.
      throw InputError(options_.input + ": " + e.what());
    }
  }
  {
    const auto t0 = Clock::now();
    cutter.flush();
    // Every tet is in the partial output; what is left is its index and footer and
    // the rename. A crash after the rename but before the checkpoint is removed
    // leaves this mark, and a resumed job then finds the output complete.
    commit(view.count, true);
    if (checkpoint_) {
      state_["output"]["finishing"] = true;
      save();
    }
    summary.seconds_write += since(t0);
  }
  summary.seconds_triangulate = since(stage_start) - summary.seconds_write;
  progress.finish();
  auto t0 = Clock::now();
  writer.finish();
  summary.seconds_write += since(t0);
  summary.query_region_releases = query_regions.releases();
  summary.seconds_writer_busy = writer.busy_seconds();
  summary.seconds_writer_wait = writer.producer_wait_seconds();
  summary.output_bytes = writer_holder->bytes_written();
  summary.tet_bytes = writer_holder->tet_bytes();
  summary.seconds_total = since(start_);
  summary.memory_ceiling = budget_.ceiling();
  summary.memory_shares = budget_.shares();
  return summary;
}

}  // namespace

namespace {
// Where a job's working files go: --tmpdir, else the output's directory.
std::string work_parent(const RunOptions& options) {
  std::string dir = options.tmpdir;
  if (dir.empty() && !io::is_std_stream(options.output)) dir = std::filesystem::path(options.output).parent_path().string();
  return dir.empty() ? "." : dir;
}
}  // namespace

std::string checkpoint_directory(const RunOptions& options) {
  // Always a directory of the job's own, inside the one the user named: the job may
  // remove what it made, never the user's directory (docs/safety.md).
  const std::string parent = options.checkpoint_dir.empty() ? work_parent(options) : options.checkpoint_dir;
  return parent + "/" + base_name(options.output) + ".ckpt";
}

namespace {

// The machine's physical memory: a larger --memory is capped there (a budget is a
// ceiling, and buffers sized from 1T fail to allocate).
std::uint64_t physical_memory_bytes() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
  return pages > 0 && page > 0 ? std::uint64_t(pages) * std::uint64_t(page) : ~std::uint64_t(0);
}

// The disk the job needs, from the input's point count (a header or the file's size;
// unknown for text and stdin, then not planned), checked before any work: IoError
// with the figures when a filesystem cannot hold its share.
std::uint64_t plan_and_check_disk(const RunOptions& o, const std::string& work_parent, bool checkpointed) {
  if (io::is_std_stream(o.input)) return 0;
  const std::optional<std::uint64_t> points = io::open_points(o.input, o.read)->count();
  if (!points) return 0;
  std::string out_dir = io::is_std_stream(o.output) ? "" : std::filesystem::path(o.output).parent_path().string();
  if (out_dir.empty()) out_dir = ".";
  const std::vector<DiskNeed> plan = plan_disk(*points, work_parent, out_dir, io::is_std_stream(o.output), checkpointed);
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

}  // namespace

RunSummary run_job(const RunOptions& requested) {
  requested.validate();
  RunOptions options = requested;
  if (const std::uint64_t ram = physical_memory_bytes(); options.memory_bytes > ram) {
    spdlog::warn("--memory {} is more than this machine's {} of memory: capped there", human_bytes(double(options.memory_bytes)),
                 human_bytes(double(ram)));
    options.memory_bytes = ram;
  }
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
    RunSummary summary = Job(options, tmp.dir(), nullptr, json::object(), claim ? &*claim : nullptr).run();
    summary.disk_planned_bytes = disk;
    return summary;
  }

  Checkpoint checkpoint(checkpoint_directory(options));
  const json identity = job_identity(options);
  json state = json::object();
  const std::string how_to_restart = "rerun with --force to discard it and start over";
  // Runs f, which reads the checkpoint; a missing field or any other damage becomes a
  // DamagedCheckpoint that says how to start over.
  auto trusting_checkpoint = [&](auto&& f) {
    try {
      f();
    } catch (const json::exception& e) {
      throw DamagedCheckpoint(checkpoint.dir() + "/state.json: damaged checkpoint (" + e.what() + "); " + how_to_restart);
    } catch (const DamagedCheckpoint& e) {
      throw DamagedCheckpoint(std::string(e.what()) + "; " + how_to_restart);
    }
  };
  checkpoint.create_and_lock();
  if (checkpoint.exists()) {
    if (options.force) {
      spdlog::info("--force: discarding the checkpoint in {}", checkpoint.dir());
      checkpoint.clear();  // the job's files only; the partial output is truncated by the writer
    } else if (!options.resume) {
      throw UsageError(checkpoint.dir() + " holds the checkpoint of an unfinished job: rerun with --resume to continue "
                       "it, or with --force to discard it and start over");
    } else {
      std::string difference;
      trusting_checkpoint([&] {
        state = checkpoint.load();
        difference = identity_difference(state.at("job"), identity);
      });
      if (!difference.empty())
        throw UsageError("cannot resume from " + checkpoint.dir() + ": " + difference + "; " + how_to_restart);
      spdlog::info("resuming the job checkpointed in {}", checkpoint.dir());
    }
  } else if (options.resume) {
    spdlog::warn("no checkpoint in {}: starting from the beginning", checkpoint.dir());
  }
  if (state.contains("output") && state["output"].value("finishing", false) && claim->created() &&
      std::filesystem::exists(options.output)) {
    // The job had finished; only the removal of its checkpoint was cut short.
    const io::TetReader finished(options.output);  // throws unless complete
    spdlog::info("the checkpointed job had finished: {} is complete", options.output);
    RunSummary summary;
    SegmentStats work;
    std::uint64_t zone_points = 0;
    counters_from(state["output"].at("counters"), work, zone_points);
    record_work(work, zone_points, summary);
    summary.resumed = true;
    summary.segments = summary.segments_resumed = state["output"].at("segments").get<std::uint64_t>();
    summary.points = finished.point_count();
    summary.input_points = finished.header().input_count;
    summary.duplicates = summary.input_points - summary.points;
    summary.output_bytes = finished.file_bytes();
    summary.tet_bytes = finished.tet_bytes();
    checkpoint.remove();
    return summary;
  }
  std::uint64_t disk = 0;
  if (!state.contains("job")) {
    const std::string parent = std::filesystem::path(checkpoint.dir()).parent_path().string();
    try {
      disk = plan_and_check_disk(options, parent.empty() ? "." : parent, true);
    } catch (...) {
      checkpoint.remove();  // made just now, and empty: nothing to resume
      throw;
    }
    state = {{"job", identity}};
    checkpoint.save(state);
  }
  try {
    RunSummary summary;
    trusting_checkpoint([&] { summary = Job(options, checkpoint.dir(), &checkpoint, state, &*claim).run(); });
    checkpoint.remove();
    summary.disk_planned_bytes = disk;
    return summary;
  } catch (const DamagedCheckpoint&) {
    throw;  // left for the user to inspect or --force away
  } catch (const InputError&) {
    // Bad input: nothing to resume.
    checkpoint.remove();
    remove_file(options.output + ".partial");
    throw;
  } catch (const BudgetTooSmall&) {
    // Refused after the first pass: nothing was written worth resuming.
    checkpoint.remove();
    remove_file(options.output + ".partial");
    throw;
  } catch (const UsageError& e) {
    // A budget too small for the sorted input: the sort's work is kept, and a resume
    // may take another --memory (the message names the one that works).
    throw UsageError(std::string(e.what()) + "; the work so far is kept in " + checkpoint.dir() +
                     ": add --resume with the new --memory");
  } catch (const std::bad_alloc&) {
    throw IoError("out of memory at --memory " + human_bytes(double(options.memory_bytes)) +
                  "; the work so far is kept in " + checkpoint.dir() +
                  ": free memory, or rerun with a smaller --memory and --resume");
  } catch (...) {
    spdlog::warn("the job's progress is kept in {}: run the same command with --resume to continue", checkpoint.dir());
    throw;
  }
}

}  // namespace tetstream::pipeline
