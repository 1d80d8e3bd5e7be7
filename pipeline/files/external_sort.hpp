#pragma once
// A generic external merge sort of fixed-size records within a memory budget.
//
//   ExternalSorter<Rec, Less> s({.memory_bytes = 256 << 20, .dir = tmp.dir(), .name = "facets"});
//   s.push(rec); ... s.push(span);         // any order; sorted runs spill to `dir`
//   s.push_sorted_run(span);               // a block the caller already sorted: one run
//   s.merge([](std::span<const Rec> batch) { ... });   // all records, in order
//
// Records are trivially copyable values (written to disk as bytes). `Less` is a strict
// weak order; records that compare equal come out of merge() in push order of their
// runs (run 0 first), and in unspecified order within one run, so give `Less` a total
// order when the output must not depend on the budget.
//
// Memory: the run buffer grows geometrically up to about 2/3 of memory_bytes (old and
// new buffers together stay within it); merge() frees it and reads the runs through
// one block each (memory_bytes / (runs + 1)), at least min_block_bytes: when there are
// too many runs for that, it first merges groups of them into longer runs (more
// passes over the data, never more memory). Data that fits in one buffer never
// touches the disk. Run files are deleted as soon as they are merged and in the
// destructor, so an exception leaves nothing behind (the caller's TempDir removes the
// directory itself). A merge of many spilled runs can take minutes, so it polls
// check_interrupted() between its output batches: Ctrl-C or SIGTERM throws Interrupted
// there (verify of 10^8 points at --memory 1G spilled 15 GB and did not stop on SIGTERM).
//
// Reduction: an optional reducer sees every sorted run before it is written (and the
// in-memory buffer before merge() serves it); it may combine records that compare
// equal (drop duplicates, add counts, ...) and returns how many records it kept at the
// front of the run. Records of one key may still arrive from several runs in merge().
//
// Threads: runs are sorted with all OpenMP threads (in-place parallel quicksort), and
// the merge runs on them too (merge_runs_in_rounds: each round merges what every run
// holds in memory up to a bound, split among the threads by splitters, with the
// sequential merge's result); push() and merge() are called from one thread.
#include "core/error.hpp"
#include "pipeline/files/parallel_merge.hpp"
#include "pipeline/files/temp_files.hpp"
#include "pipeline/util/fault.hpp"
#include "pipeline/util/interrupt.hpp"

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace tetstream::pipeline {

struct ExternalSortOptions {
  std::size_t memory_bytes = std::size_t(256) << 20;
  std::string dir;  // directory for run files (normally a TempDir's)
  // When `dir` is empty, called once at the first spill to create the directory, so
  // a sort that fits in memory creates nothing on disk.
  std::function<std::string()> make_dir;
  std::string name = "sort";                           // run files are DIR/NAME-K.run
  bool parallel = true;                                // sort runs on all OpenMP threads
  std::size_t min_block_bytes = std::size_t(1) << 20;  // smallest read block in a merge
  std::size_t batch_records = std::size_t(1) << 16;    // records per merge() callback (most)
  // For a resumable job: run files are fsynced when written, and never removed by the
  // sorter (not after a merge, not in the destructor): a checkpoint may still name
  // them, so their owner removes them once it no longer does.
  bool keep_files = false;
  // The merge gives each run's space back as it reads it (a hole punched every
  // 16 MiB read, and at the run's end: BinaryFile::give_back_before), so the runs and
  // the merged output together take about one copy of the data on disk, not two. The run files are
  // then spent as the merge goes: a resumable caller must stop naming them first.
  bool give_back_runs = false;
};

struct ExternalSortStats {
  std::uint64_t records_pushed = 0;
  std::uint64_t runs_written = 0;     // including intermediate merge passes
  std::uint64_t bytes_written = 0;    // to run files
  std::uint64_t merge_passes = 0;     // intermediate passes (0: one final merge)
  std::size_t peak_buffer_bytes = 0;  // largest run buffer held
};

namespace detail {

// In-place quicksort whose smaller halves become OpenMP tasks; parts below 32 k
// records (or past the depth limit) go to std::sort.
template <class T, class Less>
void quicksort_tasks(T* first, T* last, const Less& less, int depth) {
  constexpr std::ptrdiff_t kSerial = 1 << 15;
  while (last - first > kSerial && depth > 0) {
    T* mid = first + (last - first) / 2;
    // Median of three, as a value: the partitions below move the records.
    const T& a = *first;
    const T& b = *mid;
    const T& c = *(last - 1);
    const T pivot = less(a, b) ? (less(b, c) ? b : (less(a, c) ? c : a)) : (less(a, c) ? a : (less(b, c) ? c : b));
    T* lo_end = std::partition(first, last, [&](const T& x) { return less(x, pivot); });
    T* hi_begin = std::partition(lo_end, last, [&](const T& x) { return !less(pivot, x); });
    --depth;
    // Recurse on the smaller side as a task, loop on the larger.
    if (lo_end - first < last - hi_begin) {
      T* f = first;
      T* l = lo_end;
#pragma omp task default(none) firstprivate(f, l, depth) shared(less)
      quicksort_tasks(f, l, less, depth);
      first = hi_begin;
    } else {
      T* f = hi_begin;
      T* l = last;
#pragma omp task default(none) firstprivate(f, l, depth) shared(less)
      quicksort_tasks(f, l, less, depth);
      last = lo_end;
    }
  }
  std::sort(first, last, less);
}

int max_threads();   // omp_get_max_threads()
bool in_parallel();  // omp_in_parallel(): no nested teams
int team_size();     // omp_get_num_threads()
int thread_id();     // omp_get_thread_num()

}  // namespace detail

// Sorts in place with all OpenMP threads (not stable; no extra memory beyond the stack).
template <class T, class Less>
void parallel_sort(T* first, T* last, const Less& less) {
  if (last - first < (1 << 16) || detail::max_threads() <= 1 || detail::in_parallel()) {
    std::sort(first, last, less);
    return;
  }
#pragma omp parallel
#pragma omp single nowait
  detail::quicksort_tasks(first, last, less, 48);
}

// Stable LSD radix sort of data[0, n) by the low `bits` bits of key(x) (an unsigned
// 64-bit integer), 11 bits per pass, on all OpenMP threads for large inputs; `tmp`
// is resized to n and used as the other buffer. Passes in which every key has the
// same digit are skipped. Stability makes multi-word keys easy: sort by the least
// significant word first, then by the next, and so on.
template <class T, class Key>
void radix_sort(T* data, std::size_t n, std::vector<T>& tmp, int bits, const Key& key) {
  static_assert(std::is_trivially_copyable_v<T>);
  constexpr int kDigitBits = 11;
  constexpr std::size_t kBuckets = std::size_t(1) << kDigitBits;
  if (n < 2 || bits <= 0) return;
  if (n < 256) {
    std::stable_sort(data, data + n, [&](const T& a, const T& b) {
      const std::uint64_t m = bits >= 64 ? ~std::uint64_t(0) : (std::uint64_t(1) << bits) - 1;
      return (key(a) & m) < (key(b) & m);
    });
    return;
  }
  tmp.resize(n);
  T* src = data;
  T* dst = tmp.data();
  const int threads = (n < (std::size_t(1) << 16) || detail::in_parallel()) ? 1 : std::max(1, detail::max_threads());
  std::vector<std::size_t> count(std::size_t(threads) * kBuckets);
  for (int shift = 0; shift < bits; shift += kDigitBits) {
    bool skip = false;
#pragma omp parallel num_threads(threads) if (threads > 1)
    {
      const int nt = detail::team_size(), t = detail::thread_id();
      const std::size_t lo = n * std::size_t(t) / std::size_t(nt), hi = n * (std::size_t(t) + 1) / std::size_t(nt);
      std::size_t* c = count.data() + std::size_t(t) * kBuckets;
      std::fill(c, c + kBuckets, 0);
      for (std::size_t i = lo; i < hi; ++i) ++c[(key(src[i]) >> shift) & (kBuckets - 1)];
#pragma omp barrier
#pragma omp single
      {
        // Offsets: bucket-major, thread-minor, so the scatter is stable.
        std::size_t sum = 0;
        for (std::size_t b = 0; b < kBuckets; ++b) {
          const std::size_t before = sum;
          for (int u = 0; u < nt; ++u) {
            std::size_t& x = count[std::size_t(u) * kBuckets + b];
            const std::size_t v = x;
            x = sum;
            sum += v;
          }
          if (sum - before == n) skip = true;  // one digit value everywhere: nothing to do
        }
      }
      if (!skip)
        for (std::size_t i = lo; i < hi; ++i) dst[c[(key(src[i]) >> shift) & (kBuckets - 1)]++] = src[i];
    }
    if (!skip) std::swap(src, dst);
  }
  if (src != data) std::copy(src, src + n, data);
}

template <class T, class Less>
class ExternalSorter {
  static_assert(std::is_trivially_copyable_v<T>, "records are written to disk as bytes");

 public:
  using Reducer = std::function<std::size_t(T* first, std::size_t n)>;

  explicit ExternalSorter(ExternalSortOptions options, Less less = Less())
      : opt_(std::move(options)), less_(std::move(less)) {
    max_records_ = std::max<std::size_t>(opt_.memory_bytes / sizeof(T), 1024);
  }
  ~ExternalSorter() { remove_runs(); }
  ExternalSorter(const ExternalSorter&) = delete;
  ExternalSorter& operator=(const ExternalSorter&) = delete;

  void set_reducer(Reducer r) { reducer_ = std::move(r); }
  // ExternalSortOptions::give_back_runs, decided once the runs are written.
  void set_give_back_runs(bool give_back) { opt_.give_back_runs = give_back; }
  // Replaces the comparison sort of the runs (e.g. by a radix sort for integer keys);
  // it must order the records as `Less` does. `scratch_bytes` a record: what the sort
  // allocates beside the run (a radix sort's copy, sizeof(T)), within the budget too,
  // so the run buffer holds fewer records. Set before the first push.
  using RunSort = std::function<void(T* first, std::size_t n)>;
  void set_run_sort(RunSort s, std::size_t scratch_bytes = 0) {
    run_sort_ = std::move(s);
    max_records_ = std::max<std::size_t>(opt_.memory_bytes / (sizeof(T) + scratch_bytes), 1024);
  }

  void push(const T& r) {
    if (buf_.size() == buf_.capacity()) make_room();
    buf_.push_back(r);
    ++stats_.records_pushed;
  }
  void push(std::span<const T> rs) {
    while (!rs.empty()) {
      if (buf_.size() == buf_.capacity()) make_room();
      const std::size_t n = std::min(rs.size(), buf_.capacity() - buf_.size());
      buf_.insert(buf_.end(), rs.begin(), rs.begin() + std::ptrdiff_t(n));
      rs = rs.subspan(n);
      stats_.records_pushed += n;
    }
  }
  // A block already sorted by Less: written as one run at once (reduced first if a
  // reducer is set, which is why it is mutable). Order relative to push(): it counts
  // as pushed now, after the records buffered so far.
  void push_sorted_run(std::span<T> rs) {
    if (rs.empty()) return;
    stats_.records_pushed += rs.size();
    if (!buf_.empty()) flush_buffer();
    std::size_t n = rs.size();
    if (reducer_) n = reducer_(rs.data(), n);
    write_run(rs.data(), n);
  }

  // A run file left by an earlier process of the same job (sorted, reduced, made by
  // push_sorted_run() with the same options): it joins the runs as if just written.
  // Adopt runs before pushing anything, in their original order.
  void adopt_run(std::string path, std::uint64_t records) {
    runs_.push_back({std::move(path), records, 0});
    next_run_id_ = std::max<std::uint64_t>(next_run_id_, runs_.size());
    stats_.records_pushed += records;
  }
  // The run file written last (by push_sorted_run() or a spill): path and records.
  const std::string& last_run_path() const { return runs_.back().path; }
  std::uint64_t last_run_records() const { return runs_.back().records; }
  std::uint32_t last_run_crc() const { return runs_.back().crc; }  // CRC32C of its bytes

  std::uint64_t records_pushed() const { return stats_.records_pushed; }
  bool spilled() const { return !runs_.empty(); }
  const ExternalSortStats& stats() const { return stats_; }

  // Ends the input and calls visit(std::span<const T>) with consecutive batches of
  // the sorted records (the spans are valid during the call only). Call once.
  template <class Visit>
  void merge(Visit&& visit) {
    if (runs_.empty()) {
      // Everything is in memory.
      std::size_t n = buf_.size();
      sort_and_reduce(buf_.data(), n);
      buf_.resize(n);
      const std::size_t b = std::max<std::size_t>(opt_.batch_records, 1);
      for (std::size_t i = 0; i < buf_.size(); i += b)
        visit(std::span<const T>(buf_.data() + i, std::min(b, buf_.size() - i)));
      release_buffer();
      return;
    }
    if (!buf_.empty()) flush_buffer();
    release_buffer();
    // Fan-in: one block per run plus the output batch.
    const std::size_t min_block = std::max<std::size_t>(opt_.min_block_bytes / sizeof(T), 1);
    // The merge in rounds holds its blocks in half the budget (the round's output in the other).
    const std::size_t block_budget = opt_.memory_bytes / sizeof(T) / (merge_threads() > 1 ? 2 : 1);
    const std::size_t fan_in = std::max<std::size_t>(block_budget / (min_block + 1), 2);
    while (runs_.size() > fan_in) {
      ++stats_.merge_passes;
      std::vector<Run> next;
      for (std::size_t i = 0; i < runs_.size(); i += fan_in) {
        std::vector<Run> group(runs_.begin() + std::ptrdiff_t(i),
                               runs_.begin() + std::ptrdiff_t(std::min(runs_.size(), i + fan_in)));
        if (group.size() == 1) {
          next.push_back(group[0]);
          continue;
        }
        Run out{run_path(next_run_id_++), 0, 0};
        {
          BinaryFile f(out.path, "wb");
          merge_runs(group, [&](std::span<const T> batch) {
            f.write(batch.data(), sizeof(T), batch.size());
            out.records += batch.size();
          });
          f.close();
        }
        stats_.bytes_written += out.records * sizeof(T);
        ++stats_.runs_written;
        if (!opt_.keep_files)
          for (const Run& r : group) remove_file(r.path);
        next.push_back(out);
      }
      runs_ = std::move(next);
    }
    maybe_inject_fault("merge", 0);
    merge_runs(runs_, visit);
    remove_runs();
  }

 private:
  struct Run {
    std::string path;
    std::uint64_t records = 0;
    std::uint32_t crc = 0;  // of the file's bytes, when this sorter wrote it in one piece
  };

  // Sequential reader of one run, a block at a time; with `give_back`, the run's
  // bytes already read into the block are given back to the filesystem in steps.
  class Cursor {
   public:
    static constexpr std::uint64_t kGiveBackBytes = std::uint64_t(16) << 20;
    Cursor(const std::string& path, std::size_t block, bool give_back)
        : file_(path, give_back ? "r+b" : "rb"), block_(block), give_back_(give_back) {  // punching needs write access
      refill();
    }
    bool done() const { return pos_ == end_; }
    const T& head() const { return block_[pos_]; }
    void pop() {
      if (++pos_ == end_) refill();
    }

   private:
    void refill() {
      end_ = file_.read(block_.data(), sizeof(T), block_.size());
      served_ += end_ * sizeof(T);
      pos_ = 0;
      // The records read are in the block now: the file's copy of them is not needed
      // any more. Given back in steps, and all of it at the end of the run.
      const bool at_end = end_ < block_.size();
      if (give_back_ && (at_end || served_ >= given_back_ + kGiveBackBytes)) {
        file_.give_back_before(at_end ? served_ + 4095 : served_);
        given_back_ = served_;
      }
    }
    BinaryFile file_;
    std::vector<T> block_;
    std::size_t pos_ = 0, end_ = 0;
    bool give_back_;
    std::uint64_t served_ = 0, given_back_ = 0;  // bytes of the file read, and given back
  };

  std::string run_path(std::uint64_t id) const {
    return opt_.dir + "/" + opt_.name + "-" + std::to_string(id) + ".run";
  }

  void sort_and_reduce(T* data, std::size_t& n) {
    if (run_sort_)
      run_sort_(data, n);
    else if (opt_.parallel)
      parallel_sort(data, data + n, less_);
    else
      std::sort(data, data + n, less_);
    if (reducer_) n = reducer_(data, n);
  }

  // Grows the buffer (old + new within the budget) or spills it.
  void make_room() {
    const std::size_t cap = buf_.capacity();
    const std::size_t want = cap == 0 ? std::min<std::size_t>(max_records_ * 2 / 3, std::size_t(1) << 16)
                                      : std::min(2 * cap, max_records_ - std::min(cap, max_records_));
    if (want > cap) {
      buf_.reserve(want);
      stats_.peak_buffer_bytes = std::max(stats_.peak_buffer_bytes, buf_.capacity() * sizeof(T));
      return;
    }
    flush_buffer();
  }

  void flush_buffer() {
    std::size_t n = buf_.size();
    sort_and_reduce(buf_.data(), n);
    write_run(buf_.data(), n);
    buf_.clear();
  }

  void write_run(const T* data, std::size_t n) {
    if (opt_.dir.empty() && opt_.make_dir) opt_.dir = opt_.make_dir();
    if (opt_.dir.empty())
      throw IoError("external sort '" + opt_.name + "': out of memory budget and no temporary directory");
    Run r{run_path(next_run_id_++), n, 0};
    BinaryFile f(r.path, "wb");
    f.write(data, sizeof(T), n);
    f.close(/*sync=*/opt_.keep_files);
    r.crc = f.crc();
    stats_.bytes_written += n * sizeof(T);
    ++stats_.runs_written;
    runs_.push_back(std::move(r));
  }

  void release_buffer() {
    buf_.clear();
    buf_.shrink_to_fit();
  }

  // Threads the merge may use: OpenMP's, unless the sorter is told to stay on one or
  // is already inside a team.
  int merge_threads() const { return opt_.parallel && !detail::in_parallel() ? std::max(1, detail::max_threads()) : 1; }

  // One run of a merge in rounds, read a window at a time: the records a round did not
  // take move to the window's front at the next refill.
  class Window {
   public:
    Window(const std::string& path, std::size_t capacity, bool give_back)
        : file_(path, give_back ? "r+b" : "rb"), buf_(capacity), give_back_(give_back) {}
    std::span<const T> held() const { return {buf_.data() + pos_, end_ - pos_}; }
    bool file_done() const { return eof_; }  // every record of the run is in held() or taken
    bool done() const { return eof_ && pos_ == end_; }
    void take(std::size_t n) { pos_ += n; }
    void refill() {
      if (eof_) return;
      std::copy(buf_.begin() + std::ptrdiff_t(pos_), buf_.begin() + std::ptrdiff_t(end_), buf_.begin());
      end_ -= pos_;
      pos_ = 0;
      const std::size_t want = buf_.size() - end_;
      if (want == 0) return;
      const std::size_t got = file_.read(buf_.data() + end_, sizeof(T), want);
      end_ += got;
      served_ += got * sizeof(T);
      eof_ = got < want;
      // As Cursor: the bytes read are given back to the filesystem in steps.
      if (give_back_ && (eof_ || served_ >= given_back_ + Cursor::kGiveBackBytes)) {
        file_.give_back_before(eof_ ? served_ + 4095 : served_);
        given_back_ = served_;
      }
    }

   private:
    BinaryFile file_;
    std::vector<T> buf_;
    std::size_t pos_ = 0, end_ = 0;
    bool eof_ = false, give_back_;
    std::uint64_t served_ = 0, given_back_ = 0;
  };

  // What a round may take of each window: the records that come before the bound, the
  // least (last held record, run) of the runs with more on disk, in the merge's order
  // (record, then run). Every record still on disk comes after it, so the round's
  // output is the merged sequence's next piece. The bound's own run is taken whole,
  // so each round makes progress.
  void round_takes(const std::vector<std::unique_ptr<Window>>& win, std::vector<std::span<const T>>& take) const {
    const std::size_t k = win.size();
    std::size_t bound = k;
    for (std::size_t r = 0; r < k; ++r)
      if (!win[r]->file_done() && (bound == k || less_(win[r]->held().back(), win[bound]->held().back()))) bound = r;
    for (std::size_t r = 0; r < k; ++r) {
      const std::span<const T> held = win[r]->held();
      if (bound == k || r == bound) {
        take[r] = held;
        continue;
      }
      const T& b = win[bound]->held().back();
      take[r] = held.first(detail::cut_of(held, r, b, bound, std::size_t(0), less_));
    }
  }

  // The k-way merge on `threads` threads, in rounds: every window refilled, the
  // records before the round's bound merged in parallel (detail::parallel_merge_spans)
  // into the output block, served in batches. Half the budget holds the windows, the
  // other half the output block (never more than the windows held).
  template <class Emit>
  void merge_runs_in_rounds(const std::vector<Run>& runs, Emit&& emit, int threads) {
    const std::size_t k = runs.size();
    const std::size_t total = opt_.memory_bytes / sizeof(T);
    const std::size_t block = std::max<std::size_t>(total / 2 / k, 1);
    std::vector<std::unique_ptr<Window>> win;
    std::size_t held_most = 0;
    for (const Run& r : runs) {
      const std::size_t cap = std::clamp<std::size_t>(std::size_t(r.records), 1, block);
      win.push_back(std::make_unique<Window>(r.path, cap, opt_.give_back_runs));
      held_most += cap;
    }
    std::vector<T> out(held_most);
    std::vector<std::span<const T>> take(k);
    const std::size_t batch = std::max<std::size_t>(opt_.batch_records, 1);
    for (;;) {
      for (auto& w : win) w->refill();
      round_takes(win, take);
      std::size_t m = 0;
      for (const auto& t : take) m += t.size();
      if (m == 0) break;  // every run is done: a run with more on disk always gives its window
      detail::parallel_merge_spans(take, out.data(), less_, threads);
      for (std::size_t r = 0; r < k; ++r) win[r]->take(take[r].size());
      for (std::size_t i = 0; i < m; i += batch) {
        check_interrupted();  // a merge of spilled runs can take minutes
        emit(std::span<const T>(out.data() + i, std::min(batch, m - i)));
      }
    }
  }

  // k-way merge of `runs` into batches for `emit`; ties go to the earlier run.
  template <class Emit>
  void merge_runs(const std::vector<Run>& runs, Emit&& emit) {
    if (const int threads = merge_threads(); threads > 1) {
      merge_runs_in_rounds(runs, emit, threads);
      return;
    }
    const std::size_t k = runs.size();
    const std::size_t total = opt_.memory_bytes / sizeof(T);
    const std::size_t out_records =
        std::clamp<std::size_t>(opt_.batch_records, 1, std::max<std::size_t>(total / (k + 1), 1));
    const std::size_t block = std::max<std::size_t>((total - std::min(total, out_records)) / k, 1);
    std::vector<std::unique_ptr<Cursor>> cur;
    cur.reserve(k);
    // A run's block is never larger than the run: a generous budget is a ceiling, and
    // a block sized from it alone (a third of 8G for 1000 points) cost seconds of page
    // zeroing for nothing.
    for (const Run& r : runs)
      cur.push_back(std::make_unique<Cursor>(r.path, std::clamp<std::size_t>(std::size_t(r.records), 1, block),
                                             opt_.give_back_runs));
    detail::MergeHeap heap([&](std::size_t a, std::size_t b) { return less_(cur[a]->head(), cur[b]->head()); }, k);
    for (std::size_t i = 0; i < k; ++i)
      if (!cur[i]->done()) heap.push(i);
    heap.build();
    std::vector<T> out;
    out.reserve(out_records);
    while (!heap.empty()) {
      Cursor& c = *cur[heap.top()];
      out.push_back(c.head());
      c.pop();
      heap.advance_top(c.done());
      if (out.size() == out_records) {
        check_interrupted();  // a merge of spilled runs can take minutes
        emit(std::span<const T>(out));
        out.clear();
      }
    }
    if (!out.empty()) emit(std::span<const T>(out));
  }

  void remove_runs() {
    if (!opt_.keep_files)
      for (const Run& r : runs_) remove_file(r.path);
    runs_.clear();
  }

  ExternalSortOptions opt_;
  Less less_;
  Reducer reducer_;
  RunSort run_sort_;
  std::size_t max_records_ = 0;
  std::vector<T> buf_;
  std::vector<Run> runs_;
  std::uint64_t next_run_id_ = 0;
  ExternalSortStats stats_;
};

}  // namespace tetstream::pipeline
