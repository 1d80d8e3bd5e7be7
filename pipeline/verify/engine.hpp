#pragma once
// verify's engine (pipeline/verify.hpp says what it proves): the records of facets and
// edges, their orders, the violation log, and the Engine class, for 32- or 64-bit
// labels. Its members are defined by concern in the .ipp files beside this one and
// compiled in one translation unit (engine.cpp), which instantiates both widths:
//   engine_run.ipp      memory plan, points, the frame loop, the radix sorts;
//   frames.ipp          a frame's tets: storage, orientation, volume, facets and edges;
//   pairing.ipp         facet pairing and local Delaunay, open facets and edges, spills;
//   hull.ipp            the boundary surface (closed, convex), Euler, volume, the report;
//   ranks.ipp           a distributed job's hand-overs: the front of records whose keys
//                       another rank owns, the vertex bitmaps, boundary edges, the report.
// Internal: included only by pipeline/verify/engine.cpp (it defines non-inline helpers).
#include "pipeline/verify/verify.hpp"

#include "pipeline/util/communicator.hpp"
#include "pipeline/util/interrupt.hpp"
#include "pipeline/util/memory_budget.hpp"
#include "pipeline/verify/exact_sum.hpp"
#include "pipeline/verify/lower_stars.hpp"
#include "pipeline/verify/records.hpp"
#include "pipeline/verify/split.hpp"

#include "core/compiler.hpp"
#include "core/error.hpp"
#include "core/predicates.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/files/external_sort.hpp"
#include "pipeline/util/progress.hpp"
#include "pipeline/files/temp_files.hpp"

#include <spdlog/spdlog.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <condition_variable>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <future>
#include <limits>
#include <memory>
#include <mutex>
#include <numeric>
#include <omp.h>
#include <optional>
#include <sstream>
#include <type_traits>

namespace tetstream::pipeline::verify_engine {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// ---------------------------------------------------------------------------------
// Violations: every one counted, the first max_listed of each kind (by ordinal, then
// by text: the order in which threads find them does not matter) kept. Thread-safe;
// violations are rare, so a mutex is fine.
class ViolationLog {
 public:
  explicit ViolationLog(std::size_t max_listed) : max_(max_listed) {}

  template <class Describe>
  void add(Violation kind, std::uint64_t where, Describe&& describe) {
    const auto k = std::size_t(kind);
    counts_[k].fetch_add(1, std::memory_order_relaxed);
    if (max_ == 0) return;
    std::lock_guard<std::mutex> lock(mutex_);
    auto& list = listed_[k];
    if (list.size() == max_ && list.back().where < where) return;
    keep(list, VerifyReport::Listed{kind, where, describe()});
  }

  // Another log's counts and listed violations (a rank's, on rank 0).
  void merge(const std::array<std::uint64_t, kViolationKinds>& counts,
             const std::vector<VerifyReport::Listed>& listed) {
    for (std::size_t k = 0; k < std::size_t(kViolationKinds); ++k) counts_[k].fetch_add(counts[k]);
    std::lock_guard<std::mutex> lock(mutex_);
    for (const auto& l : listed)
      if (max_ > 0) keep(listed_[std::size_t(l.kind)], l);
  }

  void into(VerifyReport& r) const {
    for (std::size_t k = 0; k < std::size_t(kViolationKinds); ++k) {
      r.counts[k] = counts_[k].load();
      r.listed.insert(r.listed.end(), listed_[k].begin(), listed_[k].end());
    }
  }

 private:
  void keep(std::vector<VerifyReport::Listed>& list, VerifyReport::Listed l) {
    auto before = [](const VerifyReport::Listed& a, const VerifyReport::Listed& b) {
      return a.where != b.where ? a.where < b.where : a.text < b.text;
    };
    if (list.size() == max_ && !before(l, list.back())) return;
    list.insert(std::upper_bound(list.begin(), list.end(), l, before), std::move(l));
    if (list.size() > max_) list.pop_back();
  }

  std::size_t max_;
  std::mutex mutex_;
  std::array<std::atomic<std::uint64_t>, kViolationKinds> counts_{};
  std::array<std::vector<VerifyReport::Listed>, kViolationKinds> listed_;
};

// Counter-based hash for the sample (splitmix64's mixer).
inline std::uint64_t mix(std::uint64_t z) {
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

std::string labels_text(std::initializer_list<std::uint64_t> ls) {
  std::string s = "(";
  bool first = true;
  for (std::uint64_t l : ls) {
    if (!first) s += ' ';
    s += std::to_string(l);
    first = false;
  }
  return s + ")";
}

// det[b-a, c-a, d-a] in floating point: 6 times the signed volume, in T.
template <class T>
inline T det3(const double* a, const double* b, const double* c, const double* d) {
  const T bx = T(b[0]) - a[0], by = T(b[1]) - a[1], bz = T(b[2]) - a[2];
  const T cx = T(c[0]) - a[0], cy = T(c[1]) - a[1], cz = T(c[2]) - a[2];
  const T dx = T(d[0]) - a[0], dy = T(d[1]) - a[1], dz = T(d[2]) - a[2];
  return bx * (cy * dz - cz * dy) - by * (cx * dz - cz * dx) + bz * (cx * dy - cy * dx);
}

// The volume check's arithmetic. Doubles while every nonzero coordinate lies in
// [2^-250, 2^250]: nonzero differences then lie in [2^-302, 2^251], and no product of
// three overflows or underflows. Otherwise (coordinates near 1e103 made the volumes
// inf - inf = NaN, and tiny ones underflow) long double, whose 15-bit exponent holds
// any product of three differences of doubles.
static_assert(std::numeric_limits<long double>::max_exponent >= 4096,
              "verify's volume check needs a long double with a 15-bit exponent");
inline bool volume_fits_double(const double* xyz, std::size_t n) {
  for (std::size_t i = 0; i < 3 * n; ++i) {
    const double m = std::fabs(xyz[i]);
    if (m != 0 && !(m >= 0x1p-250 && m <= 0x1p250)) return false;
  }
  return true;
}

// The points by label, read in place from the source's records (VerifySource::points:
// a container's mapped PNTS section, a caller's array): floats for a float32 container
// (the predicates then see exactly the stored values, as doubles), else doubles. Not a
// copy: the pass touches a window of labels at a time (a frame's tets lie a few slabs
// apart) and hands the pages behind it back (Engine::release_points_outside), so at
// 10^9 float32 points the resident points are that window, not 12 GB.
class PointCoords {
 public:
  // A point's coordinates as doubles; converts to the const double* the predicates
  // take (valid until the end of the full expression, or while the value lives).
  struct Point {
    double c[3];
    operator const double*() const { return c; }
  };
  void assign(const VerifySource::PointRecords& records) { r_ = records; }
  bool floats() const { return r_.floats; }
  std::size_t stride() const { return r_.stride; }
  TS_FORCE_INLINE Point operator()(std::uint64_t l) const {
    const std::uint8_t* p = r_.base + l * r_.stride;
    if (r_.floats) {
      float f[3];
      std::memcpy(f, p, sizeof f);
      return {{f[0], f[1], f[2]}};
    }
    Point q;
    std::memcpy(q.c, p, sizeof q.c);
    return q;
  }
  // Asks for point l's coordinates ahead of their use (the tets' labels jump about).
  TS_FORCE_INLINE void prefetch(std::uint64_t l) const { TS_PREFETCH(r_.base + l * r_.stride); }

 private:
  VerifySource::PointRecords r_;
};

// Bit set over labels with atomic set.
class Bitmap {
 public:
  explicit Bitmap(std::uint64_t n) : words_((n + 63) / 64) {}
  void set(std::uint64_t i) {
    std::atomic_ref<std::uint64_t> w(words_[i >> 6]);
    const std::uint64_t bit = std::uint64_t(1) << (i & 63);
    if (!(w.load(std::memory_order_relaxed) & bit)) w.fetch_or(bit, std::memory_order_relaxed);
  }
  bool get(std::uint64_t i) const { return words_[i >> 6] >> (i & 63) & 1; }
  std::uint64_t count() const {
    std::uint64_t c = 0;
    for (std::uint64_t w : words_) c += std::uint64_t(std::popcount(w));
    return c;
  }
  std::size_t bytes() const { return words_.size() * 8; }
  // Bits set in [lo, hi).
  std::uint64_t count(std::uint64_t lo, std::uint64_t hi) const {
    std::uint64_t c = 0;
    for (std::uint64_t i = lo; i < hi && i % 64; ++i) c += get(i);
    std::uint64_t i = std::min(hi, (lo + 63) / 64 * 64);
    for (; i + 64 <= hi; i += 64) c += std::uint64_t(std::popcount(words_[i >> 6]));
    for (; i < hi; ++i) c += get(i);
    return c;
  }
  // The words, for a rank's hand-over of the bits of another's labels.
  std::vector<std::uint64_t>& words() { return words_; }

 private:
  std::vector<std::uint64_t> words_;
};

// Calls f(begin, end) for `parts` pieces of [0, n) whose boundaries are moved forward
// to group boundaries (is_start(i): element i starts a group), in parallel.
inline int chunk_count(std::size_t n) { return n < (1u << 14) ? 1 : std::max(1, omp_get_max_threads() * 4); }

template <class IsStart, class F>
void for_group_chunks(std::size_t n, IsStart&& is_start, F&& f, std::vector<std::size_t>& bounds) {
  const int parts = chunk_count(n);
  bounds.assign(std::size_t(parts) + 1, n);
  bounds[0] = 0;
  for (int p = 1; p < parts; ++p) {
    std::size_t b = std::max(bounds[std::size_t(p) - 1], n * std::size_t(p) / std::size_t(parts));
    while (b < n && !is_start(b)) ++b;
    bounds[std::size_t(p)] = b;
  }
#pragma omp parallel for schedule(dynamic, 1) if (parts > 1)
  for (int p = 0; p < parts; ++p) f(std::size_t(p), bounds[std::size_t(p)], bounds[std::size_t(p) + 1]);
}

// Visits the records of two sorted runs in their merged order (ties: a's first).
template <class T, class Less, class Visit>
void merge_visit(std::span<const T> a, std::span<const T> b, const Less& less, Visit&& visit) {
  const T *p = a.data(), *pe = p + a.size(), *q = b.data(), *qe = q + b.size();
  while (p != pe && q != qe) visit(less(*q, *p) ? *q++ : *p++);
  for (; p != pe; ++p) visit(*p);
  for (; q != qe; ++q) visit(*q);
}

// ---------------------------------------------------------------------------------
// The open records of one kind (facets or edges), sorted by key. Keys retire from the
// front, step after step; the retired prefix is skipped by an index, not erased, so a
// step copies the open set once (its merge with the step's records, into the other
// buffer) and not a second time. At 10^9 points about 2.5 M facets and 3.8 M edges
// stay open (N^(2/3) growth from 10^8's 0.55 M and 0.82 M), so a second copy a step
// was a cost of its own.
template <class T>
class OpenSet {
 public:
  std::span<T> records() { return std::span<T>(buffer_).subspan(from_); }
  std::size_t size() const { return buffer_.size() - from_; }
  // The first `count` records are retired (final, or handed to a spill).
  void retire_front(std::size_t count) { from_ += count; }
  // Becomes `sorted` (taken); the old buffer is handed back for reuse.
  void replace(std::vector<T>& sorted) {
    std::swap(buffer_, sorted);
    from_ = 0;
  }
  void clear() { buffer_.clear(), from_ = 0; }
  void release() { buffer_ = {}, from_ = 0; }
  void push_back(const T& r) { buffer_.push_back(r); }

 private:
  std::vector<T> buffer_;
  std::size_t from_ = 0;  // buffer_[0, from_) is retired
};

// ---------------------------------------------------------------------------------
// The engine, for 32- or 64-bit labels.
template <class L>
class Engine {
 public:
  using Facet = FacetRec<L>;
  using HullEdge = HullEdgeRec<L>;
  using Edge = EdgeKey<L>;

  Engine(const VerifySource& src, const VerifyOptions& opt, VerifyReport& rep, Communicator& comm)
      : src_(src),
        sort_axis_(src.sort_axis()),
        opt_(opt),
        rep_(rep),
        comm_(comm),
        log_(opt.max_listed),
        n_(src.point_count()),
        used_(n_),
        hull_used_(n_) {
    sampled_ = opt.sample < 1.0;
    if (sampled_) sample_cut_ = std::uint64_t(std::ldexp(opt.sample, 64));  // sample < 1: below 2^64
  }

  void run();

 private:
  struct PairCheck {
    L v[3];
    L dpos, dneg;
    std::uint64_t tpos, tneg;
  };

  TS_FORCE_INLINE PointCoords::Point P(std::uint64_t l) const { return xyz_(l); }
  // The labels as the perturbation orders them (VerifySource::sort_axis): themselves,
  // or for format 2 their points' ranks 1..K among the K given, by coordinates compared
  // from the sort axis on (the sort's order, which only the ranks' order matters to).
  template <std::size_t K>
  void perturbation_order(const std::uint64_t (&labels)[K], std::uint64_t (&order)[K]) const {
    if (sort_axis_ < 0) {
      for (std::size_t i = 0; i < K; ++i) order[i] = labels[i];
      return;
    }
    PointCoords::Point p[K];
    for (std::size_t i = 0; i < K; ++i) p[i] = P(labels[i]);
    const auto before = [&](std::size_t i, std::size_t j) {
      for (int k = 0; k < 3; ++k) {
        const int c = (sort_axis_ + k) % 3;
        if (p[i].c[c] != p[j].c[c]) return p[i].c[c] < p[j].c[c];
      }
      return labels[i] < labels[j];  // the same point twice: the caller's labels are distinct
    };
    for (std::size_t i = 0; i < K; ++i) {
      order[i] = 1;
      for (std::size_t j = 0; j < K; ++j) order[i] += before(j, i);
    }
  }
  int insphere_sos(std::uint64_t a, std::uint64_t b, std::uint64_t c, std::uint64_t d, std::uint64_t e) const {
    if (sort_axis_ >= 0) {
      const int s = core::insphere(P(a), P(b), P(c), P(d), P(e));
      if (s != 0) return s;
    }
    std::uint64_t o[5];
    perturbation_order({a, b, c, d, e}, o);
    return core::insphere_sos(P(a), P(b), P(c), P(d), P(e), o[0], o[1], o[2], o[3], o[4]);
  }
  int infinite_conflict_sos(std::uint64_t a, std::uint64_t b, std::uint64_t c, std::uint64_t e) const {
    if (sort_axis_ >= 0) {
      const int s = core::orient3d(P(a), P(b), P(c), P(e));
      if (s != 0) return s;
    }
    std::uint64_t o[4];
    perturbation_order({a, b, c, e}, o);
    return core::infinite_conflict_sos(P(a), P(b), P(c), P(e), o[0], o[1], o[2], o[3]);
  }
  bool tet_sampled(std::uint64_t ordinal) const {
    return !sampled_ || mix(opt_.seed * 0x9E3779B97F4A7C15ull + ordinal) < sample_cut_;
  }
  bool facet_sampled(L a, L b, L c) const {
    if (!sampled_) return true;
    return mix(mix(mix(opt_.seed ^ std::uint64_t(a)) + std::uint64_t(b)) + std::uint64_t(c)) < sample_cut_;
  }
  std::string tet_text(std::uint64_t ordinal, L a, L b, L c, L d) const {
    return "tet #" + std::to_string(ordinal) + " " + labels_text({a, b, c, d});
  }
  std::string facet_text(const Facet& f) const { return "facet " + labels_text({f.v[0], f.v[1], f.v[2]}); }

  // Stable radix sorts into FacetLess / edge order (records of one key keep their
  // order, which is ordinal order for freshly generated records). Every label of v is
  // in [base, base + 2^bits): the keys are taken relative to base, in fewer digits;
  // most facets' labels in [base, base + 2^near) (far: a buffer for the others).
  void sort_facets(std::vector<Facet>& v, std::vector<Facet>& tmp, std::vector<Facet>& far, std::uint64_t base,
                   int bits, int near) const;
  void sort_edges(std::vector<Edge>& v, std::vector<Edge>& tmp, std::uint64_t base, int bits) const;
  std::string make_tmpdir();
  void plan_memory();
  void load_points();
  std::size_t plan_point_window();
  void release_points_outside(std::uint64_t frame_min);
  // Checks a decoded frame (its count, every good tet's labels within the frame's
  // declared [min_label, max_label]: InputError otherwise) and puts each tet in
  // canonical form (labels sorted; flags bit 0: odd permutation, bit 1: broken, i.e. a
  // storage violation, logged when log_storage). on_good(i, ordinal, g) for each good
  // tet, g its labels as stored; called from several threads.
  // parallel: on the threads of a parallel region of its own (false inside a task).
  template <class OnGood>
  void canonicalize(std::size_t k, std::vector<L>& labels, std::vector<std::uint8_t>& flags, bool log_storage,
                    bool parallel, OnGood&& on_good);
  // ranks.ipp: the records this rank's tets make for keys later ranks own (a front),
  // sent to their owners and folded here in the order one process folds them.
  void hand_over_front(const std::vector<std::size_t>& order, const std::vector<std::uint64_t>& position);
  void replay_front(std::vector<Facet>& front, const std::vector<std::size_t>& order,
                    const std::vector<std::uint64_t>& position);
  void hand_over_bits(Bitmap& bits);
  void hand_over_hull_edges();
  std::string partial_totals();
  void merge_totals(const std::vector<std::string>& parts);
  // The pass over the frames is a pipeline on every thread (engine_run.ipp, run()):
  // prepare_frame() decodes a frame, checks its tets and builds each step's sorted
  // records into a Slot, on any thread, several frames at once; consume_frame() merges
  // the steps' records with the open sets, frame after frame in order, on one thread
  // at a time, and leaves the pairs it formed in the slot; check_pairs() tests them on
  // any thread. A frame's slot is reused `slots_` frames later, once consumed and its
  // pairs tested, so at most slots_ frames are in flight.
  struct StepRecords {
    std::vector<Facet> f;         // sorted (FacetLess), unfolded
    std::vector<Edge> e;          // sorted, unique
    std::uint64_t threshold = 0;  // keys below it are final after this step
  };
  // The buffers for building a step's records (stars: by lower stars; the others for
  // sorting them all, A: the facets and edges through a tet's smallest label, B: the
  // others), and a frame's labels and flags: one for each frame being prepared.
  struct Scratch {
    std::vector<Facet> a, b, tmp, far;
    std::vector<Edge> ea, eb, etmp, seen;  // seen: 2^kSeenBits edges
    LowerStarScratch<L> stars;
    std::vector<L> labels;
    std::vector<std::uint8_t> flags;
  };
  struct Slot {
    std::vector<StepRecords> steps;
    std::size_t step_count = 0, tets = 0;
    std::uint64_t good = 0, checked = 0;
    ExactSum volume6, error6;      // the frame's tets' (exact: any cut gives the same bits)
    std::vector<PairCheck> pairs;  // formed by consume_frame(), for check_pairs()
    std::exception_ptr error;
  };
  void prepare_frame(std::size_t k, std::uint64_t future_min, Slot& slot, Scratch& w);
  void consume_frame(Slot& slot);
  void build_step(Scratch& w, StepRecords& out, const L* canon, const std::uint8_t* flags, std::size_t lo,
                  std::size_t hi, std::uint64_t first_ordinal, bool sorted_by_min);
  // Folds runs of equal keys in place (returns the new size); new pairs go to chunk_checks_.
  std::size_t fold(Facet* first, Facet* last);
  void combine(Facet& s, const Facet& r, std::vector<PairCheck>& checks);
  // Combines each run of equal keys in [first, first + n) into its first record,
  // packed at the front; returns how many records remain.
  std::size_t fold_equal_keys(Facet* first, std::size_t n, std::vector<PairCheck>& checks);
  void check_pairs();                                      // the pairs fold() found
  void check_pairs(const std::vector<PairCheck>& checks);  // on this thread
  void retire_facets(std::uint64_t threshold);
  void final_facet(const Facet& f);
  void merge_edges(std::uint64_t threshold);
  void finish_facets();
  void finish_edges();
  void finish_hull();
  void finish();
  void totals_into_report();

  const VerifySource& src_;
  const int sort_axis_;  // src_.sort_axis(): the perturbation's order
  const VerifyOptions& opt_;
  VerifyReport& rep_;
  Communicator& comm_;
  ViolationLog log_;
  const std::uint64_t n_;
  bool sampled_ = false;
  std::uint64_t sample_cut_ = ~0ull;

  PointCoords xyz_;
  std::uint64_t behind_labels_ = 0, ahead_labels_ = 0, release_slice_labels_ = 1;  // plan_point_window()
  std::uint64_t released_below_ = 0;                                               // release_points_outside()
  double origin_[3] = {0, 0, 0};  // the lexicographically smallest point: a hull vertex
  Bitmap used_, hull_used_;

  // Budgets (bytes).
  std::size_t live_facet_budget_ = 0, live_edge_budget_ = 0, sorter_budget_ = 0;
  std::optional<TempDir> tmp_;
  std::string tmp_parent_;

  // Open facets and edges, sorted; spills.
  OpenSet<Facet> live_;
  OpenSet<Edge> live_e_;
  std::vector<Facet> merged_, spill_run_;  // the keys still open after a step; those to the spill
  std::vector<Edge> merged_e_, spill_run_e_;
  std::unique_ptr<ExternalSorter<Facet, FacetLess<L>>> facet_spill_;
  std::unique_ptr<ExternalSorter<Edge, std::less<Edge>>> edge_spill_;
  std::unique_ptr<ExternalSorter<HullEdge, HullEdgeLess<L>>> hull_sorter_;
  std::uint64_t facet_spill_min_ = ~0ull, edge_spill_min_ = ~0ull;

  std::size_t step_tets_ = 1;     // tets a step (plan_memory())
  std::size_t slots_ = 1;         // frames in flight (plan_memory())
  std::vector<Slot> slot_;        // the frames in flight, slots_ of them
  std::vector<Scratch> scratch_;  // min(threads, slots_): the frames being prepared
  std::vector<std::vector<PairCheck>> chunk_checks_;
  std::vector<std::size_t> bounds_, chunk_sizes_;
  std::vector<HullEdge> hull_edges_batch_;

  // The ranks' shares: this rank's frames and the labels it owns, [lower_, upper_).
  // Records with keys >= upper_ are made by hand_over_front(), not by the pass.
  VerifySplit split_;
  std::uint64_t lower_ = 0, upper_ = ~0ull;
  std::exception_ptr front_error_;  // the pre-pass's failure (hand_over_front)
  ExternalSortOptions hull_sort_options_;

  // Totals. Volumes summed exactly (exact_sum.hpp): the same bits however the tets are
  // cut into threads, spills and ranks.
  // *_error6_: the sums of each term's rounding bound (det3_bounded), so that the
  // comparison of the two volumes is a proof, not a tolerance: near-flat point sets have
  // volumes far below the rounding of their terms.
  ExactSum tet_volume6_, hull_volume6_, tet_error6_, hull_error6_;
  bool wide_volume_ = false;  // volumes in long double (volume_fits_double)
  BoundedDet<long double> volume6(const double* a, const double* b, const double* c, const double* d) const {
    if (wide_volume_) return det3_bounded<long double>(a, b, c, d);
    const BoundedDet<double> v = det3_bounded<double>(a, b, c, d);
    return {v.value, v.error};
  }
  std::atomic<std::uint64_t> orient_tests_{0}, insphere_tests_{0}, hull_tests_{0};
  std::uint64_t good_tets_ = 0, interior_ = 0, boundary_ = 0, bad_facets_ = 0, edges_ = 0, hull_edges_ = 0;
  std::uint64_t facets_checked_ = 0, tets_checked_ = 0;
  std::uint64_t vertices_ = 0, hull_vertices_ = 0;  // of this rank's labels, then (rank 0) of all
  double seconds_points_ = 0, seconds_tets_ = 0, seconds_final_ = 0;
};

}  // namespace tetstream::pipeline::verify_engine
