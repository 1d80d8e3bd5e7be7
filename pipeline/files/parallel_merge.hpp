#pragma once
// The k-way merge of sorted spans in memory, on several OpenMP threads, with the same
// result as the sequential one: equal records leave in span order (span 0 first), and
// within a span in their order. The external sort's merge (external_sort.hpp) calls it
// for each round of its runs' blocks.
//
// How: the output is cut into one part a thread by splitters, each a record of one
// span at one position, ordered by (record, span, position): a total order, so each
// span's records below a splitter form a prefix of it, and the part between two
// splitters is merged alone into its place (its offset: the records of all spans
// below its first splitter). The splitters come from an even sample of every span,
// weighted by the records each sample stands for, so the parts are about equal.
#include <algorithm>
#include <cstddef>
#include <exception>
#include <span>
#include <vector>

namespace tetstream::pipeline::detail {

// The heap of a k-way merge: a binary min-heap of source indices, ordered by the
// sources' current heads (`before(a, b)`: source a's head comes first; ties go to the
// smaller index, so equal records leave in source order).
template <class Before>
class MergeHeap {
 public:
  MergeHeap(Before before, std::size_t capacity) : before_(std::move(before)) { heap_.reserve(capacity); }
  void push(std::size_t source) { heap_.push_back(source); }
  void build() {
    for (std::size_t i = heap_.size(); i-- > 0;) sift_down(i);
  }
  bool empty() const { return heap_.empty(); }
  std::size_t top() const { return heap_[0]; }
  // After the top source advanced: `exhausted` drops it, otherwise it is re-placed.
  void advance_top(bool exhausted) {
    if (exhausted) {
      heap_[0] = heap_.back();
      heap_.pop_back();
    }
    if (!heap_.empty()) sift_down(0);
  }

 private:
  bool first(std::size_t a, std::size_t b) const { return before_(a, b) || (!before_(b, a) && a < b); }
  void sift_down(std::size_t i) {
    const std::size_t n = heap_.size();
    for (;;) {
      std::size_t m = i;
      const std::size_t l = 2 * i + 1, r = l + 1;
      if (l < n && first(heap_[l], heap_[m])) m = l;
      if (r < n && first(heap_[r], heap_[m])) m = r;
      if (m == i) return;
      std::swap(heap_[i], heap_[m]);
      i = m;
    }
  }
  Before before_;
  std::vector<std::size_t> heap_;
};

// Merges `in` into out[0, total) on the calling thread; ties in span order.
template <class T, class Less>
void merge_spans(const std::vector<std::span<const T>>& in, T* out, const Less& less) {
  std::vector<std::size_t> at(in.size(), 0);
  MergeHeap heap([&](std::size_t a, std::size_t b) { return less(in[a][at[a]], in[b][at[b]]); }, in.size());
  for (std::size_t s = 0; s < in.size(); ++s)
    if (!in[s].empty()) heap.push(s);
  heap.build();
  while (!heap.empty()) {
    const std::size_t s = heap.top();
    *out++ = in[s][at[s]++];
    heap.advance_top(at[s] == in[s].size());
  }
}

// A cut of every span: how many of its records come before a splitter.
using SpanCut = std::vector<std::size_t>;

// Where the splitter (record `split` of span `s` at position `pos`) cuts span `r`: the
// records x with (x, r) before (split, s), so equal records of earlier spans stay
// before it, those of later spans after it.
template <class T, class Less>
std::size_t cut_of(std::span<const T> span, std::size_t r, const T& split, std::size_t s, std::size_t pos,
                   const Less& less) {
  if (r == s) return pos;
  if (r < s) return std::size_t(std::upper_bound(span.begin(), span.end(), split, less) - span.begin());
  return std::size_t(std::lower_bound(span.begin(), span.end(), split, less) - span.begin());
}

// The cuts that split the merged output into `parts` parts of about equal size: parts
// + 1 cuts, the first all zeros, the last every span's size.
template <class T, class Less>
std::vector<SpanCut> split_spans(const std::vector<std::span<const T>>& in, std::size_t parts, const Less& less) {
  struct Sample {
    std::size_t span, pos;
    double weight;  // the records it stands for
  };
  std::vector<Sample> samples;
  std::size_t total = 0;
  for (std::size_t s = 0; s < in.size(); ++s) {
    const std::size_t n = in[s].size(), q = std::min(n, 16 * parts);
    total += n;
    for (std::size_t i = 0; i < q; ++i) samples.push_back({s, i * n / q, double(n) / double(q)});
  }
  std::sort(samples.begin(), samples.end(), [&](const Sample& a, const Sample& b) {
    const T &x = in[a.span][a.pos], &y = in[b.span][b.pos];
    if (less(x, y)) return true;
    if (less(y, x)) return false;
    return a.span != b.span ? a.span < b.span : a.pos < b.pos;
  });
  std::vector<SpanCut> cuts(parts + 1, SpanCut(in.size(), 0));
  for (std::size_t s = 0; s < in.size(); ++s) cuts[parts][s] = in[s].size();
  double below = 0;
  std::size_t next = 0;
  for (std::size_t j = 1; j < parts; ++j) {
    const double want = double(total) * double(j) / double(parts);
    while (next < samples.size() && below + samples[next].weight <= want) below += samples[next++].weight;
    if (next == samples.size()) {  // every sample is below: the part is empty
      cuts[j] = cuts[parts];
      continue;
    }
    const Sample& sp = samples[next];
    for (std::size_t r = 0; r < in.size(); ++r)
      cuts[j][r] = cut_of(in[r], r, in[sp.span][sp.pos], sp.span, sp.pos, less);
  }
  return cuts;
}

// merge_spans() on up to `threads` OpenMP threads (the same output).
template <class T, class Less>
void parallel_merge_spans(const std::vector<std::span<const T>>& in, T* out, const Less& less, int threads) {
  std::size_t total = 0;
  for (const auto& s : in) total += s.size();
  const std::size_t parts = std::size_t(std::max(1, threads));
  if (parts == 1 || total < 4096 || in.size() < 2) {
    merge_spans(in, out, less);
    return;
  }
  const std::vector<SpanCut> cuts = split_spans(in, parts, less);
  std::exception_ptr failure;  // (out of memory) rethrown after the join, never out of the region
#pragma omp parallel for schedule(static, 1) num_threads(threads)
  for (std::size_t j = 0; j < parts; ++j) {
    try {
      std::vector<std::span<const T>> piece(in.size());
      std::size_t offset = 0;
      for (std::size_t r = 0; r < in.size(); ++r) {
        offset += cuts[j][r];
        piece[r] = in[r].subspan(cuts[j][r], cuts[j + 1][r] - cuts[j][r]);
      }
      merge_spans(piece, out + offset, less);
    } catch (...) {
#pragma omp critical(tetstream_merge_failure)
      if (!failure) failure = std::current_exception();
    }
  }
  if (failure) std::rethrow_exception(failure);
}

}  // namespace tetstream::pipeline::detail
