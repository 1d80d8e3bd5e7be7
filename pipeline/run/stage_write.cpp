#include "pipeline/run/stage_write.hpp"

#include "core/error.hpp"
#include "io/tet_container.hpp"
#include "pipeline/util/fault.hpp"
#include "pipeline/util/interrupt.hpp"
#include "pipeline/util/progress.hpp"
#include "pipeline/files/temp_files.hpp"
#include "pipeline/write/label_order.hpp"
#include "pipeline/write/points_reorder.hpp"

#include <omp.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <filesystem>
#include <string>
#include <system_error>

namespace tetstream::pipeline {

using nlohmann::json;

namespace {

// The segments' integer counters, by their name in the record, with the summary's
// field for each: one table, so saving, loading and reporting cannot disagree.
struct Counter {
  const char* name;
  std::uint64_t SegmentStats::*stat;
  std::uint64_t RunSummary::*summary;
  bool may_be_absent = false;  // not in the records of a job begun before it was counted (read as 0)
};
constexpr Counter kCounters[] = {
    {"window_points", &SegmentStats::window_points, &RunSummary::window_points},
    {"repair_points", &SegmentStats::repair_points, &RunSummary::repair_points},
    {"segment_buffer_points", &SegmentStats::segment_buffer_points, &RunSummary::segment_buffer_points},
    {"zone_buffer_points", &SegmentStats::zone_buffer_points, &RunSummary::zone_buffer_points},
    {"hull_points", &SegmentStats::hull_points, &RunSummary::hull_window_points},
    {"neighbour_points", &SegmentStats::neighbour_points, &RunSummary::neighbour_points, true},
    {"range_failures", &SegmentStats::range_failures, &RunSummary::range_failures},
    {"queries", &SegmentStats::queries, &RunSummary::queries},
    {"query_points", &SegmentStats::query_points, &RunSummary::query_points},
    {"rounds", &SegmentStats::rounds, &RunSummary::rounds_max},
    {"tets", &SegmentStats::tets, &RunSummary::tets},
    {"tets_by_query", &SegmentStats::tets_by_query, &RunSummary::tets_by_query},
    {"tets_by_wall", &SegmentStats::tets_by_wall, &RunSummary::tets_by_wall, true},
    {"tets_by_rim", &SegmentStats::tets_by_rim, &RunSummary::tets_by_rim, true},
    {"rim_rechecks", &SegmentStats::rim_rechecks, &RunSummary::rim_rechecks, true},
    {"queries_spared", &SegmentStats::queries_spared, &RunSummary::queries_spared, true},
    {"empty_reach_none", &SegmentStats::empty_reach_none, &RunSummary::empty_reach_none, true},
    {"empty_reach_half", &SegmentStats::empty_reach_half, &RunSummary::empty_reach_half, true},
    {"empty_reach_one", &SegmentStats::empty_reach_one, &RunSummary::empty_reach_one, true},
    {"empty_reach_two", &SegmentStats::empty_reach_two, &RunSummary::empty_reach_two, true},
    {"empty_reach_farther", &SegmentStats::empty_reach_farther, &RunSummary::empty_reach_farther, true},
    {"tets_by_neighbour", &SegmentStats::tets_by_neighbour, &RunSummary::tets_by_neighbour, true},
    {"rim_published", &SegmentStats::rim_published, &RunSummary::rim_published, true},
    {"rim_no_room", &SegmentStats::rim_no_room, &RunSummary::rim_no_room, true},
    {"rim_from_neighbours", &SegmentStats::rim_from_neighbours, &RunSummary::rim_from_neighbours, true},
};

// The points section from the sorted file's records, in label order (with --labels
// bricks, each brick where the job's label order puts it: `order`, else null), in the
// header's coord_type (the records' own: a float32 record goes out as the float it is),
// the file's pages handed back behind.
template <class R>
void write_points(io::TetWriter& w, const SortedView& view, const R* records, const LabelOrder* order) {
  using Coord = typename R::Coord;
  const std::uint64_t chunk = order ? order->brick() : std::uint64_t(1) << 16;
  std::vector<std::uint32_t> new_of_old;
  std::vector<Coord> xyz;
  std::vector<std::uint64_t> ids;
  for (std::uint64_t first = 0; first < view.count; first += chunk) {
    const std::size_t n = std::size_t(std::min<std::uint64_t>(chunk, view.count - first));
    if (order) order->read_brick(first / chunk, new_of_old);
    xyz.resize(3 * n);
    ids.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      const R& p = records[first + i];
      const std::size_t to = order ? new_of_old[i] : i;
      for (int k = 0; k < 3; ++k) xyz[3 * to + std::size_t(k)] = p.c[k];
      ids[to] = p.original();
    }
    w.add_points(xyz.data(), ids.data(), n);
    release_mapped_pages(records + first, n * sizeof(R));
    check_interrupted();
  }
}

}  // namespace

json counters_json(const WrittenWork& work) {
  json j = {{"zone_points", work.segment_labels},
            {"seconds_build", work.stats.seconds_build},
            {"seconds_check", work.stats.seconds_check}};
  for (const Counter& c : kCounters) j[c.name] = work.stats.*c.stat;
  return j;
}

WrittenWork counters_from(const json& j) {
  WrittenWork work;
  work.segment_labels = j.at("zone_points").get<std::uint64_t>();
  for (const Counter& c : kCounters)
    work.stats.*c.stat = c.may_be_absent && !j.contains(c.name) ? 0 : j.at(c.name).get<std::uint64_t>();
  work.stats.seconds_build = j.at("seconds_build").get<double>();
  work.stats.seconds_check = j.at("seconds_check").get<double>();
  return work;
}

void record_work(const WrittenWork& work, RunSummary& s) {
  s.segment_labels = work.segment_labels;
  for (const Counter& c : kCounters) s.*c.summary = work.stats.*c.stat;
  s.seconds_build = work.stats.seconds_build;
  s.seconds_check = work.stats.seconds_check;
  s.seconds_segments = work.stats.seconds_build + work.stats.seconds_check;
}

std::uint64_t header_memory(json& state, const RunOptions& options) {
  if (!state.contains("header_memory")) state["header_memory"] = options.memory_bytes;
  return state["header_memory"].get<std::uint64_t>();
}

io::TetFileHeader container_header(const RunOptions& options, std::uint64_t memory, const SortedPoints& sorted) {
  io::TetFileHeader header;
  header.point_count = sorted.count;
  header.input_count = sorted.input_count;
  // The sorted records' precision: float32 input stays float32 (docs/format.md 3.4).
  header.coord_type = sorted.layout.float32 ? io::CoordType::kFloat32 : io::CoordType::kFloat64;
  for (int k = 0; k < 3; ++k) header.bbox_min[k] = sorted.bbox_min[k], header.bbox_max[k] = sorted.bbox_max[k];
  header.tool = "tetstream 0.1.0";
  // --labels bricks: format 2's labels (pipeline/write/label_order.hpp).
  header.version_major = options.brick_labels ? io::kVersionMajorBricks : io::kVersionMajor;
  json made = json{{"command", "run"},
                   {"input", options.input},
                   {"memory", memory},
                   {"buffer_spacings", options.buffer_spacings},
                   {"axis", std::string(1, "xyz"[sorted.axis])},
                   {"duplicates_merged", sorted.duplicates}};
  // The LAS filters decide which points (and so which original ids) the container has:
  // `convert --las-attributes` reads the input again through the same filter. Only when
  // set, so the header of every other job keeps its bytes.
  const io::PointReadOptions& read = options.read;
  if (!read.las_classes.empty()) made["las_classes"] = read.las_classes;
  if (read.las_returns != io::PointReadOptions::LasReturns::kAll)
    made["las_returns"] = read.las_returns == io::PointReadOptions::LasReturns::kLast ? "last" : "first";
  if (!read.more_inputs.empty() && read.las_filtered()) made["more_inputs"] = read.more_inputs;
  header.options = made.dump();
  return header;
}

void WriteStage::prepare() {
  const RunOptions& options = context_.options;
  json& state = context_.state;
  const std::uint64_t memory = header_memory(state, options);
  if (memory != options.memory_bytes)
    spdlog::info("resumed with --memory {}: the output keeps the budget it was started with, {}",
                 human_bytes(double(options.memory_bytes)), human_bytes(double(memory)));
  const io::TetFileHeader header = container_header(options, memory, sorted_);
  io::TetWriterOptions writer_options;
  writer_options.threads = encoders_;  // the writer stage's own team
  // Frames are cut here (FrameCutter), not by the writer: a batch is one frame.
  writer_options.frame_tets = std::uint32_t(2 * kFrameTets);
  writer_options.buffer_bytes = file_buffer_bytes_;
  writer_options.keep_partial = context_.checkpoint != nullptr;
  writer_options.claim = claim_;
  const bool fragment = !fragment_path_.empty();
  if (fragment) writer_options.claim = nullptr;  // a file of the job's own, in its work directory
  resumed_ = state.contains("output");
  if (fragment && !resumed_) {
    writer_ = io::TetWriter::fragment(fragment_path_, header, writer_options);
    return;
  }
  points_in_output_ = !fragment && sorted_.offset != 0;
  // The sort checked (resumed) or wrote (new) the points section's bytes: their CRC.
  if (points_in_output_) writer_options.points_crc = sorted_.crc32c;
  if (!resumed_ && !points_in_output_) {
    writer_ = std::make_unique<io::TetWriter>(options.output, header, writer_options);
    return;
  }
  if (!resumed_) {
    // The merge wrote the points section into the partial output: the writer goes on
    // after it (checking its bytes against the header and its checksum).
    const std::uint64_t points_end = sorted_.offset + sorted_.count * sorted_.layout.bytes() + io::kSectionTrailerSize;
    try {
      writer_ = io::TetWriter::resume(options.output, header, points_end, writer_options);
    } catch (const InputError& e) {
      throw DamagedCheckpoint(std::string(e.what()) + " (the points section the sort wrote)");
    }
    return;
  }
  const json& out = state["output"];
  const std::uint64_t committed = out.at("committed").get<std::uint64_t>();
  std::error_code ec;
  const std::string target = fragment ? fragment_path_ : options.output;
  const std::string partial = target + ".partial";
  const std::uintmax_t have = std::filesystem::file_size(partial, ec);
  if (ec || have < committed)
    throw DamagedCheckpoint(partial + ": " + (ec ? std::string("missing") : std::to_string(have) + " bytes") +
                            ", but the checkpoint committed " + std::to_string(committed) + " (damaged checkpoint)");
  try {
    writer_ = fragment ? io::TetWriter::resume_fragment(target, header, committed, writer_options)
                       : io::TetWriter::resume(target, header, committed, writer_options);
  } catch (const InputError& e) {
    throw DamagedCheckpoint(std::string(e.what()) + " (damaged checkpoint)");
  }
  first_label_ = out.at("next_label").get<std::uint64_t>();
  // The pending file: the frame being filled, then the brick held.
  const std::size_t frame_labels = 4 * out.at("pending_tets").get<std::size_t>();
  std::vector<std::uint64_t> saved(frame_labels + 4 * out.value("held_tets", std::size_t(0)));
  if (!saved.empty())
    read_file_exactly(context_.checkpoint->path(out.at("pending_file").get<std::string>()), saved.data(),
                      saved.size() * sizeof(std::uint64_t), out.at("pending_crc32c").get<std::uint32_t>());
  pending_.assign(saved.begin(), saved.begin() + std::ptrdiff_t(frame_labels));
  held_.assign(saved.begin() + std::ptrdiff_t(frame_labels), saved.end());
  work_ = counters_from(out.at("counters"));
  segments_resumed_ = segments_done_ = out.at("segments").get<std::uint64_t>();
  spdlog::info("resuming after {} segments: labels from {} of {}, {} tets written", segments_resumed_, first_label_,
               view_.count, work_.stats.tets);
}

void WriteStage::run() {
  const std::size_t encoders = std::size_t(encoders_);
  async_.emplace(*writer_, encoders, encoders);
  if (context_.options.brick_labels) {
    // Format 2's labels (pipeline/write/label_order.hpp): every brick's permutation in
    // a work file, made again by a resumed job (it depends on the points alone); a
    // rank's is named as its pending files ("rank-R-pending-": "rank-R-label-order.u32").
    order_path_ = context_.dir + "/" + pending_prefix_.substr(0, pending_prefix_.rfind("pending-")) + "label-order.u32";
    const int threads = context_.options.threads > 0 ? context_.options.threads : omp_get_num_procs();
    const StageMeter meter;
    write_label_order(
        order_path_, view_.count, view_.axis,
        [&view = view_](std::uint64_t first, std::size_t n, double* xyz) {
          view.points.visit([&](const auto* records) {
            for (std::size_t i = 0; i < n; ++i) records[first + i].xyz(xyz + 3 * i);
          });
        },
        threads);
    phases_.emplace_back("write.label_order", meter.elapsed());
    order_.emplace(order_path_, view_.count);
  } else if (!held_.empty()) {
    throw DamagedCheckpoint("the checkpoint holds a brick of tets, but the job writes sorted labels");
  }
  if (!resumed_ && !points_in_output_ && fragment_path_.empty()) {
    // The points section, in label order, on the writer's thread while the first
    // zones are triangulated (a pass over the whole sorted file, which used to hold
    // the first segment back).
    async_->add_task([&view = view_, order = order_ ? &*order_ : nullptr](io::TetWriter& w) {
      view.points.visit([&](const auto* records) { write_points(w, view, records, order); });
    });
  }
  cutter_.emplace(*async_, MemoryBudget::frame_tets_for(header_memory(context_.state, context_.options)));
  cutter_->restore(std::move(pending_));
  if (order_) {
    reorder_.emplace(*cutter_, *order_);
    reorder_->restore(held_);
    held_ = {};
  }
  if (!resumed_) record(0, false);
}

void WriteStage::add_segment(const std::vector<ZoneTets>& parts, const SegmentStats& work, std::uint64_t points,
                             std::uint64_t next_label) {
  const auto t0 = StageClock::now();
  maybe_inject_fault("write", segments_done_);
  if (reorder_) {
    merge_by_min_label(parts,
                       [this](const ZoneTets& part, std::size_t b, std::size_t e) { reorder_->add(part, b, e); });
    reorder_->done_below(next_label);
  } else {
    merge_by_min_label(parts, [this](const ZoneTets& part, std::size_t b, std::size_t e) { cutter_->add(part, b, e); });
  }
  work_.stats += work;
  work_.segment_labels += points;
  ++segments_done_;
  record(next_label, false);
  seconds_ += seconds_since(t0);
}

// Records that the output holds every tet of the labels below `next_label`: the
// writer's committed bytes, the tets of the frame being filled, the counters. The
// frame being filled is saved at once (under a name of its own); the state that names
// it is saved by the writer's thread once the frames before it are on disk, so the
// segments never wait for the writer. A crash in between leaves the previous state,
// which names the previous pending file: that one is removed only after.
// `wait`: return only when the state is saved (the job's last record).
void WriteStage::record(std::uint64_t next_label, bool wait) {
  Checkpoint* checkpoint = context_.checkpoint;
  if (!checkpoint) return;
  json& state = context_.state;
  const std::string pending_file = pending_prefix_ + std::to_string(segments_done_) + ".tets";
  // The frame being filled, then (with --labels bricks) the brick held.
  const std::vector<std::uint64_t> held = reorder_ ? reorder_->held() : std::vector<std::uint64_t>{};
  std::vector<std::uint64_t> both;
  if (!held.empty()) {
    both = cutter_->pending();
    both.insert(both.end(), held.begin(), held.end());
  }
  const std::vector<std::uint64_t>& p = held.empty() ? cutter_->pending() : both;
  const std::size_t frame_tets = cutter_->pending().size() / 4;
  if (!p.empty()) write_file_atomically(context_.dir, pending_file, p.data(), p.size() * sizeof(std::uint64_t));
  const std::string old_pending = state.contains("output") ? state["output"].value("pending_file", "") : "";
  state["output"] = {{"committed", 0},
                     {"next_label", next_label},
                     {"pending_file", pending_file},
                     {"pending_tets", frame_tets},
                     {"held_tets", held.size() / 4},
                     {"pending_crc32c", io::crc32c(p.data(), p.size() * sizeof(std::uint64_t))},
                     {"segments", segments_done_},
                     {"counters", counters_json(work_)}};
  const std::string old_path = old_pending.empty() || old_pending == pending_file ? "" : checkpoint->path(old_pending);
  auto persist = [checkpoint, old_path, disk = context_.disk](json saved, std::uint64_t committed) {
    saved["output"]["committed"] = committed;
    checkpoint->save(std::move(saved));
    if (!old_path.empty()) remove_file(old_path);
    if (disk) disk->sample();
  };
  if (wait) {
    state["output"]["committed"] = async_->checkpoint();  // drains first
    persist(state, state["output"]["committed"].get<std::uint64_t>());
  } else {
    async_->add_checkpoint([persist, saved = state](std::uint64_t committed) { persist(saved, committed); });
  }
}

void WriteStage::commit(std::uint64_t end_label) {
  const auto t0 = StageClock::now();
  if (reorder_) {
    reorder_->done_below(std::min(end_label, view_.count));
    if (reorder_->held_tets() != 0)
      throw std::logic_error("write: the tets of an unfinished brick at the end of labels [.., " +
                             std::to_string(end_label) + ")");
  }
  cutter_->flush();
  // Every tet is in the partial output; what is left is its index and footer and
  // the rename. A crash after the rename but before the checkpoint is removed
  // leaves this mark, and a resumed job then finds the output complete.
  record(std::min(end_label, view_.count), true);
  reorder_.reset();
  // Rank 0 of several: once every rank is done with the points (run_distributed).
  if (!defer_points_order_) reorder_points_section();
  if (context_.checkpoint) {
    context_.state["output"]["finishing"] = true;
    context_.save();
  }
  seconds_ += seconds_since(t0);
}

void WriteStage::reorder_points_section() {
  if (!order_) return;
  if (points_in_output_) {
    if (!claim_) throw std::logic_error("write: the points section is rewritten through the output's claim");
    const StageMeter meter;
    reorder_points(claim_->fd(), sorted_.offset, sorted_.layout, *order_);
    phases_.emplace_back("write.points_order", meter.elapsed());
  }
  order_.reset();
  remove_file(order_path_);  // 4 bytes a point, not needed past the points
}

std::uint64_t WriteStage::fragments_offset() {
  const auto t0 = StageClock::now();
  const std::uint64_t at = async_->checkpoint();  // drains first
  seconds_ += seconds_since(t0);
  return at;
}

void WriteStage::adopt_fragments(std::vector<io::FrameEntry> frames, std::uint64_t bytes) {
  async_->add_task([frames = std::move(frames), bytes](io::TetWriter& w) { w.adopt_placed_frames(frames, bytes); });
}

void WriteStage::finish() {
  const auto t0 = StageClock::now();
  async_->finish();
  seconds_ += seconds_since(t0);
}

}  // namespace tetstream::pipeline
