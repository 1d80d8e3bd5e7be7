#include "pipeline/run/stage_sort.hpp"

#include "io/tet_container.hpp"
#include "pipeline/sort/points_in_output.hpp"
#include "pipeline/run/stage_write.hpp"
#include "pipeline/window/zone_plan.hpp"

#include <spdlog/spdlog.h>

#include <filesystem>

namespace tetstream::pipeline {

using nlohmann::json;

namespace {

constexpr const char* kHullFile = "hull.labels";

json bbox_json(const double* v) { return json::array({v[0], v[1], v[2]}); }
void bbox_from(const json& j, double* v) {
  for (int k = 0; k < 3; ++k) v[k] = j.at(k).get<double>();
}
std::string base_name(const std::string& path) { return std::filesystem::path(path).filename().string(); }

json to_json(const SortProgress& p) {
  json consumed = json::array();
  for (const std::string& f : p.consumed) consumed.push_back(base_name(f));
  json runs = json::array();
  for (const SortRunFile& r : p.runs)
    runs.push_back({{"file", base_name(r.path)},
                    {"records", r.records},
                    {"crc32c", r.crc32c},
                    {"hull_file", base_name(r.hull_path)},
                    {"hull_count", r.hull_count},
                    {"hull_crc32c", r.hull_crc32c}});
  return {{"scanned", p.scanned},
          {"input_count", p.input_count},
          {"bbox_min", bbox_json(p.bbox_min)},
          {"bbox_max", bbox_json(p.bbox_max)},
          {"axis", p.axis},
          {"float32", p.float32},
          {"runs", runs},
          {"consumed", consumed}};
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
  p.float32 = j.at("float32").get<bool>();
  for (const json& f : j.at("consumed")) p.consumed.push_back(ckpt.path(f.get<std::string>()));
  const std::uint64_t record_bytes = RecordLayout::for_input(p.float32, p.input_count).bytes();
  for (const json& r : j.at("runs")) {
    SortRunFile run{ckpt.path(r.at("file").get<std::string>()),
                    r.at("records").get<std::uint64_t>(),
                    ckpt.path(r.at("hull_file").get<std::string>()),
                    r.at("hull_count").get<std::uint64_t>(),
                    r.at("crc32c").get<std::uint32_t>(),
                    r.at("hull_crc32c").get<std::uint32_t>()};
    if (!file_matches(run.path, run.records * record_bytes, run.crc32c) ||
        !file_matches(run.hull_path, run.hull_count * sizeof(std::uint64_t), run.hull_crc32c)) {
      spdlog::warn("{}: damaged or missing (size or checksum): sorting again from run {}", run.path, p.runs.size());
      break;
    }
    p.runs.push_back(run);
  }
  return p;
}

// `in_output`: the records are the points section of the partial output (the file
// named by the job's output, not one in the checkpoint's directory).
json to_json(const SortedPoints& s, bool in_output) {
  return {{"file", in_output ? std::string() : base_name(s.path)},
          {"in_output", in_output},
          {"offset", s.offset},
          {"header_memory", s.header_memory},
          {"count", s.count},
          {"input_count", s.input_count},
          {"duplicates", s.duplicates},
          {"axis", s.axis},
          {"float32", s.layout.float32},
          {"id64", s.layout.id64},
          {"bbox_min", bbox_json(s.bbox_min)},
          {"bbox_max", bbox_json(s.bbox_max)},
          {"runs", s.runs},
          {"hull_count", s.hull_labels.size()},
          {"crc32c", s.crc32c},
          {"hull_crc32c", io::crc32c(s.hull_labels.data(), s.hull_labels.size() * sizeof(std::uint64_t))}};
}
// The sorted file and the hull's labels as the checkpoint recorded them; nullopt when
// either is missing or fails its checksum (the job sorts again, and must then come to
// the same bytes: see SortStage::run).
std::optional<SortedPoints> sorted_from(const json& j, const Checkpoint& ckpt, const RunOptions& options) {
  SortedPoints s;
  const bool in_output = j.at("in_output").get<bool>();
  s.path = in_output ? options.output + ".partial" : ckpt.path(j.at("file").get<std::string>());
  s.offset = j.at("offset").get<std::uint64_t>();
  s.header_memory = j.at("header_memory").get<std::uint64_t>();
  s.count = j.at("count").get<std::uint64_t>();
  s.input_count = j.at("input_count").get<std::uint64_t>();
  s.duplicates = j.at("duplicates").get<std::uint64_t>();
  s.axis = j.at("axis").get<int>();
  s.layout = RecordLayout{j.at("float32").get<bool>(), j.at("id64").get<bool>()};
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
  const std::uint64_t bytes = s.count * s.layout.bytes();
  if (in_output ? !region_matches(s.path, s.offset, bytes, s.crc32c) : !file_matches(s.path, bytes, s.crc32c)) {
    spdlog::warn("{}: damaged or missing (size or checksum): sorting again", s.path);
    return std::nullopt;
  }
  return s;
}

}  // namespace

void SortStage::prepare() {
  json& state = context_.state;
  if (state.contains("sorted")) {
    if (std::optional<SortedPoints> kept = sorted_from(state["sorted"], *context_.checkpoint, context_.options)) {
      sorted_ = std::move(*kept);
      done_ = true;
      renew_header_budget();
      return;
    }
    // "sorted" stays in the state until the new file replaces it: a crash while
    // sorting again still finds the checksum to come to.
    expected_crc_ = state["sorted"].at("crc32c").get<std::uint32_t>();
  }
  if (context_.checkpoint && state.contains("sort"))
    progress_ = sort_progress_from(state["sort"], *context_.checkpoint);
}

// The output's header names the budget of the process that starts writing its frames
// (WriteStage records it): the bytes of an uninterrupted run at that budget. The
// points section, written by the sort, names the sorting process's; when a resumed
// process with another --memory finds no frame started yet (a budget refused after
// the sort, a kill before the first segment), the header is rewritten for its budget
// before anything maps the points (the records move when its length changes).
void SortStage::renew_header_budget() {
  const RunOptions& options = context_.options;
  json& state = context_.state;
  if (sorted_.offset == 0 || !claim_ || state.contains("header_memory") || state.contains("output") ||
      sorted_.header_memory == options.memory_bytes)
    return;
  sorted_.header_memory = options.memory_bytes;
  rewrite_points_header(claim_->fd(), sorted_, container_header(options, options.memory_bytes, sorted_), true);
  state["sorted"] = to_json(sorted_, true);
  context_.save();
}

std::function<io::TetFileHeader(const SortedPoints&)> SortStage::points_header() const {
  const std::uint64_t memory = context_.state.value("header_memory", context_.options.memory_bytes);
  return [&options = context_.options, memory](const SortedPoints& s) { return container_header(options, memory, s); };
}

const SortedPoints& SortStage::adopt(SortedPoints sorted) {
  sorted_ = std::move(sorted);
  sorted_.header_memory = context_.state.value("header_memory", context_.options.memory_bytes);
  check_sorted_again();
  return sorted_;
}

void SortStage::check_sorted_again() const {
  if (expected_crc_ && sorted_.crc32c != *expected_crc_)
    throw DamagedCheckpoint(sorted_.path +
                            ": sorted again after a checksum failure, the points differ from the "
                            "checkpoint's (damaged checkpoint, or the input changed)");
}

const SortedPoints& SortStage::run() {
  if (done_) return sorted_;
  const RunOptions& options = context_.options;
  PointSortOptions sort_options;
  sort_options.memory_bytes = std::size_t(options.memory_bytes);
  sort_options.budget = &budget_;
  sort_options.run_points = std::size_t(options.sort_run_points);
  // Before any run is written: a budget that cannot hold even the thinnest windows
  // of this many points is refused now, not after the sort.
  sort_options.on_scanned = [this](const SortProgress& p) {
    refuse_budget_before_sort(p, context_.options.plan_options(), threads_);
  };
  sort_options.progress = options.progress;
  // The budget the header names: the writer's record when it started (a sort done
  // again under committed frames), else this process's (see prepare).
  const std::uint64_t memory = context_.state.value("header_memory", options.memory_bytes);
  if (claim_) {
    // The merge writes straight into the output's points section (no second copy).
    sort_options.open_sink = [this](const SortedPoints& before) -> std::unique_ptr<SortedSink> {
      return std::make_unique<OutputPointsSink>(claim_->fd(), claim_->path() + ".partial", points_header(), before);
    };
  }
  if (context_.checkpoint) {
    sort_options.resume = &progress_;
    sort_options.on_step = [this](const SortProgress& p) {
      context_.state["sort"] = to_json(p);
      context_.save();
    };
  }
  {
    const ScopedThreads threads(threads_);
    sorted_ = sort_points(options.input, options.read, sort_options, context_.dir);
  }
  if (sorted_.offset != 0) sorted_.header_memory = memory;
  check_sorted_again();
  return sorted_;
}

void SortStage::commit() {
  if (done_ || !context_.checkpoint) return;
  write_file_atomically(context_.dir, kHullFile, sorted_.hull_labels.data(),
                        sorted_.hull_labels.size() * sizeof(std::uint64_t));
  context_.state["sorted"] = to_json(sorted_, sorted_.offset != 0);
  context_.state.erase("sort");
  context_.save();
  // The runs are merged into the sorted file, and the state no longer names them.
  for (const SortRunFile& r : progress_.runs) remove_file(r.path), remove_file(r.hull_path);
  for (const std::string& f : progress_.consumed) remove_file(f);
  done_ = true;
}

}  // namespace tetstream::pipeline
