#include "pipeline/run.hpp"

#include "core/error.hpp"
#include "io/tet_reader.hpp"
#include "io/tet_writer.hpp"
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
#include <chrono>
#include <cmath>
#include <filesystem>
#include <atomic>
#include <exception>
#include <malloc.h>
#include <omp.h>

namespace tetstream::pipeline {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// Bytes per window point at the kernel's peak: tets (~6.7 x 33 bytes), vertex arrays,
// coordinates, labels, the mapped sorted record and the spatial index, with headroom
// for the allocator; measured with /usr/bin/time on uniform data.
constexpr double kWindowBytesPerPoint = 480;
// Bytes per zone point for the emitted tets (4 x 8-byte labels, ~6.7 tets).
constexpr double kOutputBytesPerPoint = 220;
// What the budget keeps for everything else: writer buffers, encoders, the runtime.
constexpr double kFixedOverheadBytes = 64.0 * (1 << 20);


// Tets per frame, about: a frame is cut at the first change of minimum label after
// this many tets. The segments emit their tets grouped by minimum label and the
// zones follow each other in label order, so the job's whole stream is ordered by
// minimum label, and the frames (each a set, stored canonically by the codec) are
// the same for any segment plan or thread count: the same budget gives the same
// bytes, and two budgets give the same frames but for the header's options.
constexpr std::size_t kFrameTets = std::size_t(1) << 18;

class FrameCutter {
 public:
  explicit FrameCutter(io::TetWriter& writer) : writer_(writer) {}

  void add(const std::vector<std::uint64_t>& tets) {
    pending_.insert(pending_.end(), tets.begin(), tets.end());
    std::size_t begin = 0;
    const std::size_t n = pending_.size() / 4;
    while (n - begin > kFrameTets) {
      std::size_t cut = begin + kFrameTets;
      while (cut < n && min_label(cut) == min_label(cut - 1)) ++cut;
      if (cut == n) break;  // the group may continue in the next batch
      write(begin, cut);
      begin = cut;
    }
    pending_.erase(pending_.begin(), pending_.begin() + std::ptrdiff_t(4 * begin));
  }
  void flush() {
    if (!pending_.empty()) write(0, pending_.size() / 4);
    pending_.clear();
  }

 private:
  std::uint64_t min_label(std::size_t t) const {
    const std::uint64_t* q = &pending_[4 * t];
    return std::min(std::min(q[0], q[1]), std::min(q[2], q[3]));
  }
  void write(std::size_t begin, std::size_t end) {
    writer_.add_tets(std::span<const std::uint64_t>(pending_.data() + 4 * begin, 4 * (end - begin)));
  }

  io::TetWriter& writer_;
  std::vector<std::uint64_t> pending_;
};

}  // namespace

std::uint64_t parse_memory_size(const std::string& text) {
  std::size_t used = 0;
  double value = 0;
  try {
    value = std::stod(text, &used);
  } catch (const std::exception&) {
    throw UsageError("bad memory size '" + text + "': expected e.g. 512M, 4G");
  }
  std::string unit = text.substr(used);
  double scale = 1;
  if (unit == "" || unit == "B") scale = 1;
  else if (unit == "K" || unit == "KiB" || unit == "k") scale = 1024.0;
  else if (unit == "M" || unit == "MiB") scale = 1024.0 * 1024;
  else if (unit == "G" || unit == "GiB") scale = 1024.0 * 1024 * 1024;
  else if (unit == "T" || unit == "TiB") scale = 1024.0 * 1024 * 1024 * 1024;
  else throw UsageError("bad memory size '" + text + "': unknown unit '" + unit + "' (use K, M, G, T)");
  if (!(value > 0) || !std::isfinite(value)) throw UsageError("bad memory size '" + text + "': must be positive");
  return std::uint64_t(value * scale);
}

void RunOptions::validate() const {
  if (input.empty()) throw UsageError("no input given");
  if (output.empty()) throw UsageError("no output given (-o OUT.tets)");
  if (memory_bytes < (std::uint64_t(64) << 20))
    throw UsageError("--memory " + std::to_string(memory_bytes >> 20) + "M is too small: at least 64M");
  if (!(buffer_spacings >= 0) || buffer_spacings > 1000) throw UsageError("--buffer must be in [0, 1000]");
  read.validate();
}

RunSummary run_job(const RunOptions& options) {
  options.validate();
  const auto start = Clock::now();
  RunSummary summary;
  std::string tmpdir = options.tmpdir;
  if (tmpdir.empty()) {
    tmpdir = std::filesystem::path(options.output).parent_path().string();
    if (tmpdir.empty()) tmpdir = ".";
  }
  TempDir tmp(tmpdir, "tetstream-run");

  // ---- stage 1: external sort ----
  PointSortOptions sort_options;
  sort_options.memory_bytes = std::size_t(options.memory_bytes);
  sort_options.progress = options.progress;
  SortedPoints sorted = sort_points(options.input, options.read, sort_options, tmp);
  summary.input_points = sorted.input_count;
  summary.points = sorted.count;
  summary.duplicates = sorted.duplicates;
  summary.axis = sorted.axis;
  summary.seconds_sort = since(start);
  spdlog::info("sorted {} points ({} duplicates merged) along {} in {} runs, {:.1f}s", sorted.count,
               sorted.duplicates, "xyz"[sorted.axis], sorted.runs, summary.seconds_sort);
  if (sorted.count < 4) throw InputError(options.input + ": fewer than 4 distinct points");

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

  PointIndex index;
  index.build(view.points, view.count, view.axis, /*release_file_pages=*/true);
  view.index = &index;

  // The global hull: the hull of the runs' candidates.
  {
    std::vector<double> xyz;
    for (std::uint64_t label : sorted.hull_labels) xyz.insert(xyz.end(), view.points[label].xyz, view.points[label].xyz + 3);
    for (std::uint32_t i : hull_vertex_candidates(xyz.data(), sorted.hull_labels.size()))
      view.hull_labels.push_back(sorted.hull_labels[i]);
    std::sort(view.hull_labels.begin(), view.hull_labels.end());
    summary.hull_vertices = view.hull_labels.size();
  }

  // ---- segment plan from the budget ----
  double extent[3], volume = 1;
  for (int k = 0; k < 3; ++k) {
    extent[k] = view.bbox_max[k] - view.bbox_min[k];
    volume *= std::max(extent[k], 1e-300);
  }
  const double spacing = std::cbrt(volume / double(view.count));
  const double buffer_width = options.buffer_spacings * spacing;
  const double points_per_length = double(view.count) / std::max(extent[view.axis], 1e-300);
  const double buffer_points = std::min(double(view.count), 2 * buffer_width * points_per_length);
  const int threads = options.threads > 0 ? options.threads : omp_get_max_threads();
  std::uint64_t zone_points = options.zone_points;
  if (zone_points == 0) {
    // Each of the `threads` segments in flight gets an equal share of the budget.
    // 20% of the budget is kept back for allocator slack and the pages of the sorted
    // file that a window's queries touch (released after each segment).
    const double avail = (0.8 * double(options.memory_bytes) - kFixedOverheadBytes - double(index.memory_bytes())) / threads -
                         kWindowBytesPerPoint * (buffer_points + double(view.hull_labels.size()));
    const double z = avail / (kWindowBytesPerPoint + kOutputBytesPerPoint);
    if (z < 1000)
      throw UsageError("--memory " + std::to_string(options.memory_bytes >> 20) +
                       "M is too small for this input: each window needs about " +
                       std::to_string(std::uint64_t((buffer_points + view.hull_labels.size()) * kWindowBytesPerPoint) >> 20) +
                       "M for its buffers and hull alone");
    zone_points = std::uint64_t(z);
  }
  const auto plans = plan_segments(view, zone_points, buffer_width);
  summary.segments = plans.size();
  spdlog::info("{} segments of ~{} points, buffer {:.3g} ({} spacings, ~{:.0f} points), {} hull vertices", plans.size(),
               plans.empty() ? 0 : plans[0].zone_end - plans[0].zone_begin, buffer_width, options.buffer_spacings,
               buffer_points, view.hull_labels.size());

  // ---- writer: header and points ----
  io::TetFileHeader header;
  header.point_count = view.count;
  header.input_count = sorted.input_count;
  header.coord_type = io::CoordType::kFloat64;
  for (int k = 0; k < 3; ++k) header.bbox_min[k] = view.bbox_min[k], header.bbox_max[k] = view.bbox_max[k];
  header.tool = "tetstream 0.1.0";
  header.options = nlohmann::json{{"command", "run"},
                                  {"input", options.input},
                                  {"memory", options.memory_bytes},
                                  {"buffer_spacings", options.buffer_spacings},
                                  {"axis", std::string(1, "xyz"[view.axis])},
                                  {"duplicates_merged", sorted.duplicates}}
                       .dump();
  io::TetWriterOptions writer_options;
  writer_options.threads = options.threads;
  // Frames are cut here (FrameCutter), not by the writer: a batch is one frame.
  writer_options.frame_tets = 2 * kFrameTets;
  io::TetWriter writer(options.output, header, writer_options);
  {
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
      writer.add_points(xyz.data(), ids.data(), n);
      release_mapped_pages(view.points + first, n * sizeof(SortedPoint));
    }
    release_mapped_pages(mapping.data(), mapping.size());
  }

  // ---- stages 2-5: segments, `threads` at a time, written in segment order ----
  // Each thread triangulates whole segments (they are independent given the sorted
  // file); the ordered region hands their tets to the writer in plan order, so the
  // bytes do not depend on the thread count, and a finished segment waits there for
  // its predecessors: at most `threads` segments are in memory at once, which is
  // what the zone size above was planned for.
  Progress progress("triangulating", "points", view.count, options.progress);
  FrameCutter cutter(writer);
  std::exception_ptr failure;
  std::atomic<bool> cancelled{false};
  const auto stage_start = Clock::now();
  const std::int64_t segment_count = std::int64_t(plans.size());
#pragma omp parallel for ordered schedule(dynamic, 1) num_threads(threads)
  for (std::int64_t i = 0; i < segment_count; ++i) {
    const SegmentPlan& plan = plans[std::size_t(i)];
    std::vector<std::uint64_t> tets;
    SegmentStats s;
    if (!cancelled.load()) {
      try {
        check_interrupted();
        s = triangulate_segment(view, plan, tets);
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
        try {
          const auto t0 = Clock::now();
          cutter.add(tets);
          summary.seconds_write += since(t0);
        } catch (...) {
#pragma omp critical(tetstream_run_failure)
          if (!failure) failure = std::current_exception();
          cancelled = true;
        }
        summary.seconds_segments += s.seconds_build + s.seconds_check;
        summary.zone_points += plan.zone_end - plan.zone_begin;
        summary.window_points += s.window_points;
        summary.repair_points += s.repair_points;
        summary.range_failures += s.range_failures;
        summary.queries += s.queries;
        summary.rounds_max = std::max(summary.rounds_max, s.rounds);
        summary.tets += s.tets;
        spdlog::debug("segment [{}, {}): window {} (+{} repairs), {} range failures, {} queries, {} rounds, {} tets, "
                      "build {:.2f}s check {:.2f}s, kernel {}",
                      plan.zone_begin, plan.zone_end, s.window_points, s.repair_points, s.range_failures, s.queries,
                      s.rounds, s.tets, s.seconds_build, s.seconds_check, human_bytes(double(s.kernel_bytes)));
        progress.add(plan.zone_end - plan.zone_begin);
      }
      std::vector<std::uint64_t>().swap(tets);
      release_mapped_pages(mapping.data(), mapping.size());
      malloc_trim(0);  // hand the segment's freed heap back, so resident memory tracks the windows
    }
  }
  if (failure) std::rethrow_exception(failure);
  {
    const auto t0 = Clock::now();
    cutter.flush();
    summary.seconds_write += since(t0);
  }
  summary.seconds_triangulate = since(stage_start) - summary.seconds_write;
  progress.finish();
  auto t0 = Clock::now();
  writer.finish();
  summary.seconds_write += since(t0);
  summary.output_bytes = writer.bytes_written();
  summary.tet_bytes = io::TetReader(options.output).tet_bytes();
  summary.seconds_total = since(start);
  return summary;
}

}  // namespace tetstream::pipeline
