#include "pipeline/run.hpp"

#include "core/error.hpp"
#include "io/tet_writer.hpp"
#include "pipeline/hull.hpp"
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
#include <malloc.h>
#include <sys/mman.h>

namespace tetstream::pipeline {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// Bytes per window point at the kernel's peak: tets (~6.7 x 33 bytes), vertex arrays,
// coordinates, labels, the mapped sorted record and the spatial index, with headroom
// for the allocator; measured with /usr/bin/time on uniform data.
constexpr double kWindowBytesPerPoint = 400;
// Bytes per zone point for the emitted tets (4 x 8-byte labels, ~6.7 tets).
constexpr double kOutputBytesPerPoint = 220;
// What the budget keeps for everything else: writer buffers, encoders, the runtime.
constexpr double kFixedOverheadBytes = 64.0 * (1 << 20);

// Returns pages of the mapping to the page cache, so that resident memory stays that
// of the current window however much of the file the job has read.
void release_pages(const void* data, std::size_t bytes) {
  const std::size_t page = 4096;
  const auto begin = reinterpret_cast<std::uintptr_t>(data);
  const std::uintptr_t aligned = begin & ~(page - 1);
  madvise(reinterpret_cast<void*>(aligned), bytes + (begin - aligned), MADV_DONTNEED);
}

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
  index.build(view.points, view.count, view.axis);
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
  std::uint64_t zone_points = options.zone_points;
  if (zone_points == 0) {
    const double avail = double(options.memory_bytes) - kFixedOverheadBytes -
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
    }
    release_pages(mapping.data(), mapping.size());
  }

  // ---- stages 2-5: segments ----
  Progress progress("triangulating", "points", view.count, options.progress);
  std::vector<std::uint64_t> tets;
  for (const SegmentPlan& plan : plans) {
    tets.clear();
    auto t0 = Clock::now();
    const SegmentStats s = triangulate_segment(view, plan, tets);
    summary.seconds_triangulate += since(t0);
    t0 = Clock::now();
    writer.add_tets(std::span<const std::uint64_t>(tets));
    summary.seconds_write += since(t0);
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
    release_pages(mapping.data(), mapping.size());
    malloc_trim(0);  // hand the segment's freed heap back, so resident memory tracks the window
    progress.add(plan.zone_end - plan.zone_begin);
  }
  progress.finish();
  std::vector<std::uint64_t>().swap(tets);
  auto t0 = Clock::now();
  writer.finish();
  summary.seconds_write += since(t0);
  summary.output_bytes = writer.bytes_written();
  summary.seconds_total = since(start);
  return summary;
}

}  // namespace tetstream::pipeline
