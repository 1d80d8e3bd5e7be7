#include "pipeline/sort/point_sort.hpp"

#include "pipeline/util/memory_budget.hpp"

#include "io/tet_container.hpp"

#include "core/error.hpp"
#include "pipeline/files/checkpoint.hpp"
#include "pipeline/util/fault.hpp"
#include "pipeline/sort/point_sort_detail.hpp"
#include "pipeline/files/temp_files.hpp"

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

using namespace sort_detail;  // the pieces both sorts share

// Pass 2: the input read again into runs, each sorted, its hull vertex candidates
// found (their original indices into hull_originals), written in records R.
template <class R>
void write_runs(typename RecordSort<R>::Sorter& sorter, const std::string& source,
                const io::PointReadOptions& source_options, const PointSortOptions& options, const std::string& dir,
                const SortShares& shares, SortProgress& done, SortedPoints& result,
                std::unordered_set<std::uint64_t>& hull_originals) {
  const bool resumable = options.resume != nullptr;
  const int axis = result.axis;
  const std::size_t run_points = options.run_points ? options.run_points : shares.run_points;
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
  std::vector<double> chunk(3 * kReadChunk);
  auto reader = io::open_points(source, source_options);
  Progress progress("sorting", "points", result.input_count, options.progress);
  std::uint64_t next_original = 0;
  std::vector<double> run_xyz;
  std::vector<std::uint64_t> run_hull;
  auto flush_run = [&] {
    if (run.empty()) return;
    sort_detail::sort_and_push_run<R>(sorter, run, axis, shares, run_xyz, run_hull, hull_originals, result.runs);
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

// The merge: the runs into one sorted file of records R, exact duplicates dropped
// (the first, the smallest original index, stays), the hull candidates' labels found.
// The default sink: sorted.points, a file of the sort's own.
class FileSink final : public SortedSink {
 public:
  explicit FileSink(std::string path) : path_(std::move(path)), out_(path_, "wb") {}
  void write(const void* data, std::size_t bytes) override { out_.write(data, 1, bytes); }
  void finish(SortedPoints& result, bool sync) override {
    out_.close(sync);
    result.path = path_;
    result.offset = 0;
    result.crc32c = out_.crc();
  }

 private:
  std::string path_;
  BinaryFile out_;
};

// Pass 2 and the merge, in records R (the sort's shares taken from the ledger first).
template <class R>
void sort_runs_and_merge(const std::string& source, const io::PointReadOptions& source_options,
                         const PointSortOptions& options, const std::string& dir, SortProgress& done,
                         SortedPoints& result) {
  auto t0 = Clock::now();
  StageMeter meter;
  std::optional<MemoryBudget> own_budget;
  const SortShares shares = sort_shares(options, result.input_count, own_budget);
  ExternalSortOptions sorter_options;
  sorter_options.memory_bytes = shares.merge_bytes;
  sorter_options.dir = dir;
  sorter_options.name = "points";
  // Batches of 2^18 records (7 MiB at most, beside the merge's share): each is one
  // parallel region of the duplicate filter, and a region's barrier is a cost of its
  // own when the cores are shared (2^16-record batches made the merge slower on two
  // threads than on one on a loaded machine).
  sorter_options.batch_records = std::size_t(1) << 18;
  sorter_options.keep_files = options.resume != nullptr;
  typename RecordSort<R>::Sorter sorter(sorter_options, typename RecordSort<R>::Less{result.axis});
  std::unordered_set<std::uint64_t> hull_originals;  // original indices of candidates
  write_runs<R>(sorter, source, source_options, options, dir, shares, done, result, hull_originals);
  result.seconds_runs = since(t0);
  result.time_runs = meter.elapsed();

  t0 = Clock::now();
  meter.restart();
  // The merge punches holes in the runs behind its reads: from here on they are not
  // runs a resumed job could adopt. The state says so before the first hole (a job
  // resumed during the merge sorts its runs again from the input).
  if (options.resume) {
    for (const SortRunFile& r : done.runs) done.consumed.push_back(r.path), done.consumed.push_back(r.hull_path);
    done.runs.clear();
    if (options.on_step) options.on_step(done);
  }
  sorter.set_give_back_runs(true);
  const std::unique_ptr<SortedSink> sink =
      options.open_sink ? options.open_sink(result) : std::make_unique<FileSink>(dir + "/sorted.points");
  sort_detail::merge_runs_into<R>(sorter, hull_originals, *sink, /*sync=*/options.resume != nullptr, options.progress,
                                  result.input_count, result);
  result.seconds_merge = since(t0);
  result.time_merge = meter.elapsed();
}
}  // namespace

SortedPoints sort_points(const std::string& input, const io::PointReadOptions& read_options,
                         const PointSortOptions& options, const std::string& dir) {
  SortedPoints result;
  SortProgress fresh;
  SortProgress& done = options.resume ? *options.resume : fresh;
  const bool resumable = options.resume != nullptr;

  // ---- pass 1: bounding box and count (stdin is spooled so it can be read again) ----
  auto t0 = Clock::now();
  const StageMeter scan_meter;
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
    std::vector<double> chunk(3 * kReadChunk);
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
    done.float32 = reader->float32_input();
    done.axis = int(std::max_element(extent, extent + 3) - extent);
    done.scanned = true;
    if (options.on_step) options.on_step(done);
  }
  result.input_count = done.input_count;
  result.axis = done.axis;
  for (int k = 0; k < 3; ++k) result.bbox_min[k] = done.bbox_min[k], result.bbox_max[k] = done.bbox_max[k];
  result.seconds_scan = since(t0);
  result.time_scan = scan_meter.elapsed();

  if (options.on_scanned) options.on_scanned(done);
  result.layout = RecordLayout::for_input(done.float32, done.input_count);
  with_record(result.layout,
              [&](auto r) { sort_runs_and_merge<decltype(r)>(source, source_options, options, dir, done, result); });
  return result;
}

}  // namespace tetstream::pipeline
