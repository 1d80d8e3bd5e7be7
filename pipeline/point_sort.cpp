#include "pipeline/point_sort.hpp"

#include "pipeline/memory_budget.hpp"

#include "io/tet_container.hpp"

#include "core/error.hpp"
#include "pipeline/checkpoint.hpp"
#include "pipeline/external_sort.hpp"
#include "pipeline/fault.hpp"
#include "pipeline/hull.hpp"
#include "pipeline/interrupt.hpp"
#include "pipeline/progress.hpp"
#include "pipeline/temp_files.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <optional>
#include <chrono>
#include <cmath>
#include <cstring>
#include <exception>
#include <filesystem>
#include <unordered_set>

namespace tetstream::pipeline {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

constexpr std::size_t kReadChunk = 1 << 16;  // points per read() call

}  // namespace

SortedPoints sort_points(const std::string& input, const io::PointReadOptions& read_options,
                         const PointSortOptions& options, const std::string& dir) {
  SortedPoints result;
  std::vector<double> chunk(3 * kReadChunk);
  SortProgress fresh;
  SortProgress& done = options.resume ? *options.resume : fresh;
  const bool resumable = options.resume != nullptr;

  // ---- pass 1: bounding box and count (stdin is spooled so it can be read again) ----
  auto t0 = Clock::now();
  std::string source = input;
  io::PointReadOptions source_options = read_options;
  if (io::is_std_stream(input)) {
    if (resumable) throw std::logic_error("sort_points: stdin cannot be resumed");
    source = dir + "/stdin.f64";
    source_options = io::PointReadOptions{};
    source_options.format = io::PointFormat::kRaw;
    source_options.type = io::ScalarType::kFloat64;
  }
  if (!done.scanned) {
    auto reader = io::open_points(input, read_options);
    std::unique_ptr<BinaryFile> spool_file;
    if (source != input) spool_file = std::make_unique<BinaryFile>(source, "wb");
    Progress progress("reading", "points", reader->count().value_or(0), options.progress);
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    std::uint64_t count = 0;
    while (std::size_t n = reader->read(chunk.data(), kReadChunk)) {
      for (std::size_t i = 0; i < n; ++i)
        for (int k = 0; k < 3; ++k) {
          lo[k] = std::min(lo[k], chunk[3 * i + k]);
          hi[k] = std::max(hi[k], chunk[3 * i + k]);
        }
      if (spool_file) spool_file->write(chunk.data(), 3 * sizeof(double), n);
      check_interrupted();
      count += n;
      progress.add(n);
    }
    if (spool_file) spool_file->close();
    progress.finish();
    if (count == 0) throw InputError(reader->source_name() + ": no points");
    double extent[3];
    for (int k = 0; k < 3; ++k) {
      done.bbox_min[k] = lo[k], done.bbox_max[k] = hi[k];
      extent[k] = hi[k] - lo[k];
    }
    done.input_count = count;
    done.axis = int(std::max_element(extent, extent + 3) - extent);
    done.scanned = true;
    if (options.on_step) options.on_step(done);
  }
  result.input_count = done.input_count;
  result.axis = done.axis;
  for (int k = 0; k < 3; ++k) result.bbox_min[k] = done.bbox_min[k], result.bbox_max[k] = done.bbox_max[k];
  result.seconds_scan = since(t0);

  // ---- pass 2: sorted runs, each with its hull vertex candidates ----
  t0 = Clock::now();
  const int axis = result.axis;
  const auto before = [axis](const SortedPoint& a, const SortedPoint& b) { return sorted_before(a, b, axis); };
  if (options.on_scanned) options.on_scanned(done);
  // The sort's shares of the ledger (run buffer, hull pieces, merge), sized for this
  // input's count: a small input takes little of a large budget.
  std::optional<MemoryBudget> own_budget;
  MemoryBudget* budget = options.budget;
  if (!budget) budget = &own_budget.emplace(options.memory_bytes, result.input_count, detail::max_threads(), detail::max_threads());
  budget->set_points(result.input_count);
  const SortShares shares = budget->plan_sort();
  const std::size_t run_points = options.run_points ? options.run_points : shares.run_points;
  const std::size_t hull_piece = shares.hull_piece_points;
  const int hull_threads = shares.hull_threads;
  ExternalSortOptions sorter_options;
  sorter_options.memory_bytes = shares.merge_bytes;
  sorter_options.dir = dir;
  sorter_options.name = "points";
  sorter_options.keep_files = resumable;
  ExternalSorter<SortedPoint, decltype(before)> sorter(sorter_options, before);
  std::unordered_set<std::uint64_t> hull_originals;  // original indices of candidates
  // Runs an earlier process finished: adopted as they are, their points skipped below.
  std::uint64_t skip = 0;
  for (const SortRunFile& r : done.runs) {
    sorter.adopt_run(r.path, r.records);
    std::vector<std::uint64_t> hull(r.hull_count);
    read_file_exactly(r.hull_path, hull.data(), hull.size() * sizeof(std::uint64_t), r.hull_crc32c);
    hull_originals.insert(hull.begin(), hull.end());
    skip += r.records;
  }
  result.runs = done.runs.size();
  std::vector<SortedPoint> run;
  run.reserve(std::min<std::uint64_t>(run_points, result.input_count - std::min(skip, result.input_count)));
  {
    auto reader = io::open_points(source, source_options);
    Progress progress("sorting", "points", result.input_count, options.progress);
    std::uint64_t next_original = 0;
    std::vector<double> run_xyz;
    std::vector<std::uint64_t> run_hull;
    auto flush_run = [&] {
      if (run.empty()) return;
      parallel_sort(run.data(), run.data() + run.size(), before);
      run_xyz.resize(3 * run.size());
      for (std::size_t i = 0; i < run.size(); ++i) std::memcpy(&run_xyz[3 * i], run[i].xyz, 3 * sizeof(double));
      // Hull candidates piece by piece, so the kernels' memory stays a fraction of
      // the budget even when most points are on the hull (a thin shell); the pieces
      // are independent and run on all threads, their results joined in order.
      run_hull.clear();
      const std::size_t pieces = (run.size() + hull_piece - 1) / hull_piece;
      std::vector<std::vector<std::uint32_t>> piece_hull(pieces);
      std::exception_ptr failure;  // (out of memory) rethrown after the join, never out of the region
#pragma omp parallel for schedule(dynamic, 1) num_threads(hull_threads)
      for (std::size_t p = 0; p < pieces; ++p) {
        const std::size_t first = p * hull_piece, n = std::min(hull_piece, run.size() - first);
        try {
          piece_hull[p] = hull_vertex_candidates(&run_xyz[3 * first], n);
        } catch (...) {
#pragma omp critical(tetstream_hull_failure)
          if (!failure) failure = std::current_exception();
        }
      }
      if (failure) std::rethrow_exception(failure);
      for (std::size_t p = 0; p < pieces; ++p)
        for (std::uint32_t i : piece_hull[p]) run_hull.push_back(run[p * hull_piece + i].original);
      hull_originals.insert(run_hull.begin(), run_hull.end());
      maybe_inject_fault("sort-run", result.runs);
      sorter.push_sorted_run(std::span<SortedPoint>(run));
      ++result.runs;
      if (resumable) {
        SortRunFile r;
        r.path = sorter.last_run_path();
        r.records = sorter.last_run_records();
        r.hull_path = r.path + ".hull";
        r.hull_count = run_hull.size();
        r.crc32c = sorter.last_run_crc();
        r.hull_crc32c = io::crc32c(run_hull.data(), run_hull.size() * sizeof(std::uint64_t));
        const std::string name = std::filesystem::path(r.hull_path).filename().string();
        write_file_atomically(dir, name, run_hull.data(), run_hull.size() * sizeof(std::uint64_t));
        done.runs.push_back(r);
        if (options.on_step) options.on_step(done);
      }
      run.clear();
    };
    while (std::size_t n = reader->read(chunk.data(), kReadChunk)) {
      for (std::size_t i = 0; i < n; ++i) {
        if (next_original < skip) {  // in a run an earlier process finished
          ++next_original;
          continue;
        }
        SortedPoint p;
        std::memcpy(p.xyz, &chunk[3 * i], sizeof p.xyz);
        p.original = next_original++;
        run.push_back(p);
        if (run.size() == run_points) flush_run();
      }
      progress.add(n);
      check_interrupted();
    }
    flush_run();
    progress.finish();
    if (next_original != result.input_count)
      throw InputError(reader->source_name() + ": changed while being read (" + std::to_string(result.input_count) +
                       " points, then " + std::to_string(next_original) + ")");
  }
  std::vector<SortedPoint>().swap(run);
  result.seconds_runs = since(t0);

  // ---- merge, dropping exact duplicates ----
  t0 = Clock::now();
  result.path = dir + "/sorted.points";
  {
    BinaryFile out(result.path, "wb");
    std::vector<SortedPoint> block;
    block.reserve(std::size_t(1) << 15);
    SortedPoint last{};
    bool have_last = false;
    std::vector<std::uint64_t> hull_labels;
    Progress progress("merging", "points", result.input_count, options.progress);
    sorter.merge([&](std::span<const SortedPoint> batch) {
      check_interrupted();
      for (const SortedPoint& p : batch) {
        const bool candidate = hull_originals.count(p.original) != 0;
        // Equal as numbers (so -0.0 == 0.0), as the kernel compares points.
        if (have_last && p.xyz[0] == last.xyz[0] && p.xyz[1] == last.xyz[1] && p.xyz[2] == last.xyz[2]) {
          ++result.duplicates;  // the first occurrence (smallest original index) stays
          if (candidate) hull_labels.push_back(result.count - 1);
          continue;
        }
        if (candidate) hull_labels.push_back(result.count);
        block.push_back(p);
        last = p;
        have_last = true;
        ++result.count;
        if (block.size() == block.capacity()) {
          out.write(block.data(), sizeof(SortedPoint), block.size());
          block.clear();
        }
      }
      // Counted as read from the runs, duplicates included: the total is the input count.
      progress.add(batch.size());
    });
    out.write(block.data(), sizeof(SortedPoint), block.size());
    out.close(/*sync=*/resumable);
    result.crc32c = out.crc();
    progress.finish();
    std::sort(hull_labels.begin(), hull_labels.end());
    hull_labels.erase(std::unique(hull_labels.begin(), hull_labels.end()), hull_labels.end());
    result.hull_labels = std::move(hull_labels);
  }
  result.seconds_merge = since(t0);
  return result;
}

}  // namespace tetstream::pipeline
