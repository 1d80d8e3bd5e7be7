#include "pipeline/verify.hpp"

#include "pipeline/interrupt.hpp"

#include "core/error.hpp"
#include "core/predicates.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/external_sort.hpp"
#include "pipeline/progress.hpp"
#include "pipeline/temp_files.hpp"

#include <spdlog/spdlog.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
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

namespace tetstream::pipeline {

const char* violation_name(Violation v) {
  switch (v) {
    case Violation::kStorage: return "storage";
    case Violation::kOrientation: return "orientation";
    case Violation::kDuplicateTet: return "duplicate_tet";
    case Violation::kFacetOverused: return "facet_overused";
    case Violation::kFacetSameSide: return "facet_same_side";
    case Violation::kDelaunay: return "delaunay";
    case Violation::kHullOpen: return "hull_open";
    case Violation::kHullConvex: return "hull_convex";
    case Violation::kHullTopology: return "hull_topology";
    case Violation::kMissingPoint: return "missing_point";
    case Violation::kEuler: return "euler";
    case Violation::kVolume: return "volume";
    case Violation::kCount: break;
  }
  return "?";
}

void VerifyOptions::validate() const {
  if (!(sample > 0.0) || sample > 1.0) throw UsageError("--sample must be in (0, 1]");
  if (memory_bytes < (std::uint64_t(16) << 20)) throw UsageError("--memory must be at least 16M");
  if (!(volume_tolerance >= 0.0)) throw UsageError("the volume tolerance must be >= 0");
  if (batch_tets == 0) throw UsageError("batch_tets must be at least 1");
}

std::uint64_t VerifyReport::violations() const {
  std::uint64_t n = 0;
  for (std::uint64_t c : counts) n += c;
  return n;
}

std::string VerifyReport::summary() const {
  std::ostringstream s;
  s << (ok() ? "VALID" : "INVALID");
  if (sampled) s << " (sample " << sample << ")";
  s << ": " << points << " points, " << tets << " tets";
  if (ok() && !sampled) s << " are the Delaunay triangulation of the points";
  s << "\n";
  s << "  vertices " << vertices << ", facets " << facets << " (" << interior_facets << " interior, "
    << boundary_facets << (sampled ? " unpaired in the sample" : " on the hull") << ")";
  if (!sampled) {
    s << ", edges " << edges << ", V-E+F-T " << euler << "\n";
    s << "  hull: " << hull_vertices << " vertices, " << hull_edges << " edges, V-E+F " << hull_euler
      << "; volume: tets " << tet_volume << ", hull " << hull_volume << ", relative difference " << volume_rel_error;
  }
  s << "\n  checked: " << tets_checked << " tets (orient3d), " << facets_checked << " facets, " << insphere_tests
    << " insphere, " << hull_tests << " hull edge tests";
  if (spilled_records) s << "; spilled " << spilled_records << " records (" << human_bytes(double(spill_bytes)) << ")";
  s << "\n  violations: " << violations();
  for (int k = 0; k < kViolationKinds; ++k)
    if (counts[std::size_t(k)]) s << ", " << violation_name(Violation(k)) << " " << counts[std::size_t(k)];
  for (const Listed& l : listed) s << "\n  " << violation_name(l.kind) << ": " << l.text;
  return s.str();
}

// ---------------------------------------------------------------------------------
// Sources.

MemorySource::MemorySource(std::vector<double> xyz, std::vector<std::uint64_t> tets, std::size_t batch_tets)
    : xyz_(std::move(xyz)), tets_(std::move(tets)) {
  if (batch_tets == 0) batch_tets = 1;
  const std::uint64_t t = tets_.size() / 4;
  for (std::uint64_t first = 0; first < t; first += batch_tets) {
    Batch b;
    b.first_tet = first;
    b.tet_count = std::min<std::uint64_t>(batch_tets, t - first);
    b.min_label = std::numeric_limits<std::uint64_t>::max();
    for (std::uint64_t i = 4 * first; i < 4 * (first + b.tet_count); ++i) b.min_label = std::min(b.min_label, tets_[i]);
    batches_.push_back(b);
  }
}

void MemorySource::read_points(std::uint64_t first, std::size_t n, double* xyz) const {
  std::copy(xyz_.begin() + std::ptrdiff_t(3 * first), xyz_.begin() + std::ptrdiff_t(3 * (first + n)), xyz);
}

void MemorySource::read_batch(std::size_t k, std::vector<std::uint32_t>& labels) const {
  const Batch& b = batches_[k];
  labels.resize(4 * b.tet_count);
  for (std::size_t i = 0; i < labels.size(); ++i) {
    const std::uint64_t l = tets_[4 * b.first_tet + i];
    if (l > 0xFFFFFFFFu) throw InputError("memory: label " + std::to_string(l) + " does not fit 32 bits");
    labels[i] = std::uint32_t(l);
  }
}

void MemorySource::read_batch(std::size_t k, std::vector<std::uint64_t>& labels) const {
  const Batch& b = batches_[k];
  labels.assign(tets_.begin() + std::ptrdiff_t(4 * b.first_tet),
                tets_.begin() + std::ptrdiff_t(4 * (b.first_tet + b.tet_count)));
}

ContainerSource::ContainerSource(const io::TetReader& reader) : reader_(reader) {}
std::uint64_t ContainerSource::point_count() const { return reader_.point_count(); }
std::uint64_t ContainerSource::tet_count() const { return reader_.tet_count(); }
std::size_t ContainerSource::batch_count() const { return std::size_t(reader_.frame_count()); }
VerifySource::Batch ContainerSource::batch(std::size_t k) const {
  const io::FrameEntry& f = reader_.frames()[k];
  return Batch{f.first_tet, f.tet_count, f.base_label};
}
void ContainerSource::read_points(std::uint64_t first, std::size_t n, double* xyz) const {
  reader_.read_points(first, n, xyz, nullptr);
  // The reader maps the whole file; the copied records are not needed again, so drop
  // their pages from this process's resident set (a read-only file mapping: they are
  // read back from the file if anyone touches them again).
  const std::span<const std::uint8_t> rec = reader_.point_records();
  const std::size_t size = reader_.header().point_record_bytes();
  const std::uintptr_t page = std::uintptr_t(::sysconf(_SC_PAGESIZE));
  const std::uintptr_t b = std::uintptr_t(rec.data() + first * size), e = b + n * size;
  const std::uintptr_t lo = (b + page - 1) / page * page, hi = e / page * page;
  if (hi > lo) ::madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_DONTNEED);
}
void ContainerSource::read_batch(std::size_t k, std::vector<std::uint32_t>& labels) const {
  reader_.read_frame(k, labels);
}
void ContainerSource::read_batch(std::size_t k, std::vector<std::uint64_t>& labels) const {
  reader_.read_frame(k, labels);
}
std::string ContainerSource::name() const { return reader_.path(); }
std::string ContainerSource::directory() const {
  const std::filesystem::path p = std::filesystem::path(reader_.path()).parent_path();
  return p.empty() ? std::string(".") : p.string();
}

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// ---------------------------------------------------------------------------------
// Violations: every one counted, the first max_listed of each kind (by ordinal) kept.
// Thread-safe; violations are rare, so a mutex is fine.
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
    if (list.size() == max_ && list.back().where <= where) return;
    VerifyReport::Listed l{kind, where, describe()};
    auto at = std::upper_bound(list.begin(), list.end(), where,
                               [](std::uint64_t w, const VerifyReport::Listed& x) { return w < x.where; });
    list.insert(at, std::move(l));
    if (list.size() > max_) list.pop_back();
  }

  void into(VerifyReport& r) const {
    for (std::size_t k = 0; k < std::size_t(kViolationKinds); ++k) {
      r.counts[k] = counts_[k].load();
      r.listed.insert(r.listed.end(), listed_[k].begin(), listed_[k].end());
    }
  }

 private:
  std::size_t max_;
  std::mutex mutex_;
  std::array<std::atomic<std::uint64_t>, kViolationKinds> counts_{};
  std::array<std::vector<VerifyReport::Listed>, kViolationKinds> listed_;
};

// ---------------------------------------------------------------------------------
// Records.
//
// FacetRec: one facet (triangle) as seen so far. v: its labels, sorted. x: flags in
// the top byte, a payload in the low 56 bits:
//   single  (no flag)  one tet: d is its fourth vertex, payload its ordinal; kSide set
//                      when that tet, if positively oriented, is (v0, v1, v2, d) in this
//                      order, i.e. d lies on the positive side of (v0, v1, v2);
//   kPair              two tets on opposite sides, already checked: d is the vertex on
//                      the positive side, the payload the one on the negative side;
//   kBad               already reported (repeated or overused); payload: an ordinal.
constexpr std::uint64_t kPayload = (std::uint64_t(1) << 56) - 1;
constexpr std::uint64_t kSide = std::uint64_t(1) << 56;
constexpr std::uint64_t kPair = std::uint64_t(1) << 57;
constexpr std::uint64_t kBad = std::uint64_t(1) << 58;

template <class L>
struct FacetRec {
  L v[3];
  L d;
  std::uint64_t x;
};
static_assert(sizeof(FacetRec<std::uint32_t>) == 24);

template <class L>
struct FacetLess {
  bool operator()(const FacetRec<L>& a, const FacetRec<L>& b) const {
    if (a.v[0] != b.v[0]) return a.v[0] < b.v[0];
    if (a.v[1] != b.v[1]) return a.v[1] < b.v[1];
    if (a.v[2] != b.v[2]) return a.v[2] < b.v[2];
    const std::uint64_t pa = a.x & kPayload, pb = b.x & kPayload;
    if (pa != pb) return pa < pb;
    return a.x < b.x;
  }
};

template <class L>
bool same_key(const FacetRec<L>& a, const FacetRec<L>& b) {
  return a.v[0] == b.v[0] && a.v[1] == b.v[1] && a.v[2] == b.v[2];
}

// A boundary edge of a boundary facet: u < v, w the facet's third vertex, x: kSide when
// the facet, oriented outwards, runs u -> v; payload the tet's ordinal.
template <class L>
struct HullEdgeRec {
  L u, v, w;
  std::uint64_t x;
};

template <class L>
struct HullEdgeLess {
  bool operator()(const HullEdgeRec<L>& a, const HullEdgeRec<L>& b) const {
    if (a.u != b.u) return a.u < b.u;
    if (a.v != b.v) return a.v < b.v;
    return a.x < b.x;
  }
};

// Edge keys: (u, v), u < v, ordered by u then v. 32-bit labels pack into one integer.
struct Edge64 {
  std::uint64_t u, v;
  bool operator<(const Edge64& o) const { return u != o.u ? u < o.u : v < o.v; }
  bool operator==(const Edge64& o) const = default;
};
template <class L>
using EdgeKey = std::conditional_t<sizeof(L) == 4, std::uint64_t, Edge64>;
inline std::uint64_t make_edge(std::uint32_t u, std::uint32_t v) { return std::uint64_t(u) << 32 | v; }
inline Edge64 make_edge(std::uint64_t u, std::uint64_t v) { return {u, v}; }
inline std::uint64_t edge_u(std::uint64_t e) { return e >> 32; }
inline std::uint64_t edge_u(const Edge64& e) { return e.u; }

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

// Stable k-way merge of sorted ranges into out (ties: the earlier range first).
template <class T, class Less>
void multiway_merge(std::vector<std::pair<const T*, const T*>>& rs, T* out, const Less& less) {
  std::erase_if(rs, [](const auto& r) { return r.first == r.second; });
  if (rs.empty()) return;
  if (rs.size() == 1) {
    std::copy(rs[0].first, rs[0].second, out);
    return;
  }
  if (rs.size() == 2) {
    std::merge(rs[0].first, rs[0].second, rs[1].first, rs[1].second, out, less);
    return;
  }
  detail::MergeHeap heap([&](std::size_t a, std::size_t b) { return less(*rs[a].first, *rs[b].first); }, rs.size());
  for (std::size_t i = 0; i < rs.size(); ++i) heap.push(i);
  heap.build();
  while (!heap.empty()) {
    auto& r = rs[heap.top()];
    *out++ = *r.first++;
    heap.advance_top(r.first == r.second);
  }
}

// Merges sorted inputs into `out`, one key range per thread (ties: the earlier input
// first). Ranges are cut between keys (key_less), so the records of one key meet in
// one range. finish(r, first, m) post-processes range r in place on its thread and
// returns how many records it kept at the front; the kept records are then packed.
// Returns their number.
template <class T, class Less, class KeyLess, class Finish>
std::size_t merge_ranges(const std::vector<std::span<const T>>& in, std::vector<T>& out, const Less& less,
                         const KeyLess& key_less, std::vector<std::size_t>& kept, Finish&& finish) {
  std::size_t total = 0, biggest = 0;
  for (std::size_t i = 0; i < in.size(); ++i) {
    total += in[i].size();
    if (in[i].size() > in[biggest].size()) biggest = i;
  }
  if (out.capacity() < total) {
    out = {};
    out.reserve(total);  // exactly: no doubling of the biggest buffer
  }
  out.resize(total);
  const std::size_t ranges = total < (1u << 15) ? 1 : std::size_t(std::max(1, omp_get_max_threads()));
  const std::size_t k = in.size();
  // bounds[i * (ranges + 1) + r]: where range r starts in input i; splitters are
  // evenly spaced keys of the biggest input.
  std::vector<std::size_t> bounds(k * (ranges + 1)), offset(ranges + 1, 0);
  for (std::size_t r = 0; r <= ranges; ++r) {
    const bool inner = r > 0 && r < ranges;
    const T* split = inner ? &in[biggest][in[biggest].size() * r / ranges] : nullptr;
    for (std::size_t i = 0; i < k; ++i) {
      std::size_t b = r == 0 ? 0 : in[i].size();
      if (inner) b = std::size_t(std::lower_bound(in[i].begin(), in[i].end(), *split, key_less) - in[i].begin());
      bounds[i * (ranges + 1) + r] = b;
      offset[r] += b;
    }
  }
  kept.assign(ranges, 0);
#pragma omp parallel for num_threads(int(ranges)) schedule(static, 1) if (ranges > 1)
  for (std::int64_t rr = 0; rr < std::int64_t(ranges); ++rr) {
    const std::size_t r = std::size_t(rr);
    std::vector<std::pair<const T*, const T*>> rs(k);
    for (std::size_t i = 0; i < k; ++i)
      rs[i] = {in[i].data() + bounds[i * (ranges + 1) + r], in[i].data() + bounds[i * (ranges + 1) + r + 1]};
    T* first = out.data() + offset[r];
    multiway_merge(rs, first, less);
    kept[r] = finish(r, first, offset[r + 1] - offset[r]);
  }
  std::size_t w = 0;
  for (std::size_t r = 0; r < ranges; ++r) {
    if (w != offset[r] && kept[r]) std::memmove(static_cast<void*>(out.data() + w), out.data() + offset[r], kept[r] * sizeof(T));
    w += kept[r];
  }
  return w;
}

// ---------------------------------------------------------------------------------
// The engine, for 32- or 64-bit labels.
template <class L>
class Engine {
 public:
  using Facet = FacetRec<L>;
  using HullEdge = HullEdgeRec<L>;
  using Edge = EdgeKey<L>;

  Engine(const VerifySource& src, const VerifyOptions& opt, VerifyReport& rep)
      : src_(src), opt_(opt), rep_(rep), log_(opt.max_listed), n_(src.point_count()), used_(n_), hull_used_(n_) {
    sampled_ = opt.sample < 1.0;
    label_bits_ = std::max(1, int(std::bit_width(n_ > 0 ? n_ - 1 : 0)));
    if (sampled_) sample_cut_ = std::uint64_t(std::ldexp(opt.sample, 64));  // sample < 1: below 2^64
  }

  void run();

 private:
  struct PairCheck {
    L v[3];
    L dpos, dneg;
    std::uint64_t tpos, tneg;
  };

  const double* P(std::uint64_t l) const { return xyz_.data() + 3 * l; }
  bool tet_sampled(std::uint64_t ordinal) const { return !sampled_ || mix(opt_.seed * 0x9E3779B97F4A7C15ull + ordinal) < sample_cut_; }
  bool facet_sampled(L a, L b, L c) const {
    if (!sampled_) return true;
    return mix(mix(mix(opt_.seed ^ std::uint64_t(a)) + std::uint64_t(b)) + std::uint64_t(c)) < sample_cut_;
  }
  std::string tet_text(std::uint64_t ordinal, L a, L b, L c, L d) const {
    return "tet #" + std::to_string(ordinal) + " " + labels_text({a, b, c, d});
  }
  std::string facet_text(const Facet& f) const { return "facet " + labels_text({f.v[0], f.v[1], f.v[2]}); }

  // Stable radix sorts into FacetLess / edge order (records of one key keep their
  // order, which is ordinal order for freshly generated records).
  void sort_facets(std::vector<Facet>& v, std::vector<Facet>& tmp) const;
  void sort_edges(std::vector<Edge>& v, std::vector<Edge>& tmp) const;
  std::string make_tmpdir();
  void plan_memory();
  void load_points();
  void process_frame(std::size_t k, std::vector<L>& labels, std::uint64_t future_min);
  // Per-thread buffers of a step's slice of tets.
  struct Part {
    std::vector<Facet> a, b, f, tmp;   // A and B facets, merged
    std::vector<Edge> ea, eb, e, etmp;
  };
  void process_step(const L* canon, const std::uint8_t* flags, std::size_t count, std::uint64_t first_ordinal,
                    bool sorted_by_min, std::uint64_t threshold);
  void build_part(Part& part, const L* canon, const std::uint8_t* flags, std::size_t lo, std::size_t hi,
                  std::uint64_t first_ordinal, bool sorted_by_min);
  // Folds runs of equal keys in place (returns the new size); new pairs go to chunk_checks_.
  std::size_t fold(Facet* first, Facet* last);
  void combine(Facet& s, const Facet& r, std::vector<PairCheck>& checks);
  // Combines each run of equal keys in [first, first + n) into its first record,
  // packed at the front; returns how many records remain.
  std::size_t fold_equal_keys(Facet* first, std::size_t n, std::vector<PairCheck>& checks);
  void check_pairs();  // the pairs fold() found
  void check_pairs(const std::vector<PairCheck>& checks);  // on this thread
  void retire_facets(std::uint64_t threshold);
  void final_facet(const Facet& f);
  void merge_edges(std::uint64_t threshold);
  void finish_facets();
  void finish_edges();
  void finish_hull();
  void finish();

  const VerifySource& src_;
  const VerifyOptions& opt_;
  VerifyReport& rep_;
  ViolationLog log_;
  const std::uint64_t n_;
  bool sampled_ = false;
  std::uint64_t sample_cut_ = ~0ull;

  std::vector<double> xyz_;
  double origin_[3] = {0, 0, 0};  // the lexicographically smallest point: a hull vertex
  Bitmap used_, hull_used_;

  // Budgets (bytes).
  std::size_t live_facet_budget_ = 0, live_edge_budget_ = 0, sorter_budget_ = 0;
  std::optional<TempDir> tmp_;
  std::string tmp_parent_;

  // Open facets and edges, sorted; spills.
  std::vector<Facet> live_, merged_;
  std::vector<Edge> live_e_, merged_e_;
  std::unique_ptr<ExternalSorter<Facet, FacetLess<L>>> facet_spill_;
  std::unique_ptr<ExternalSorter<Edge, std::less<Edge>>> edge_spill_;
  std::unique_ptr<ExternalSorter<HullEdge, HullEdgeLess<L>>> hull_sorter_;
  std::uint64_t facet_spill_min_ = ~0ull, edge_spill_min_ = ~0ull;

  int label_bits_ = 1;  // bits of the largest label
  std::vector<Part> parts_;
  std::vector<std::vector<PairCheck>> chunk_checks_;
  std::vector<std::size_t> bounds_, chunk_sizes_;
  std::vector<HullEdge> hull_edges_batch_;

  // Totals.
  long double tet_volume6_ = 0, hull_volume6_ = 0;
  bool wide_volume_ = false;  // volumes in long double (volume_fits_double)
  long double volume6(const double* a, const double* b, const double* c, const double* d) const {
    return wide_volume_ ? det3<long double>(a, b, c, d) : det3<double>(a, b, c, d);
  }
  std::atomic<std::uint64_t> orient_tests_{0}, insphere_tests_{0}, hull_tests_{0};
  std::uint64_t good_tets_ = 0, interior_ = 0, boundary_ = 0, bad_facets_ = 0, edges_ = 0, hull_edges_ = 0;
  std::uint64_t facets_checked_ = 0, tets_checked_ = 0;
  double seconds_points_ = 0, seconds_tets_ = 0, seconds_final_ = 0;
};

template <class L>
void Engine<L>::sort_facets(std::vector<Facet>& v, std::vector<Facet>& tmp) const {
  const int b = label_bits_;
  if (3 * b <= 64) {
    radix_sort(v.data(), v.size(), tmp, 3 * b, [b](const Facet& f) {
      return std::uint64_t(f.v[0]) << (2 * b) | std::uint64_t(f.v[1]) << b | std::uint64_t(f.v[2]);
    });
  } else {
    for (int j = 2; j >= 0; --j)
      radix_sort(v.data(), v.size(), tmp, b, [j](const Facet& f) { return std::uint64_t(f.v[j]); });
  }
}

template <class L>
void Engine<L>::sort_edges(std::vector<Edge>& v, std::vector<Edge>& tmp) const {
  const int b = label_bits_;
  if constexpr (sizeof(L) == 4) {
    radix_sort(v.data(), v.size(), tmp, 2 * b,
               [b](std::uint64_t e) { return (e >> 32) << b | (e & 0xFFFFFFFFu); });
  } else if (2 * b <= 64) {
    radix_sort(v.data(), v.size(), tmp, 2 * b, [b](const Edge& e) { return e.u << b | e.v; });
  } else {
    radix_sort(v.data(), v.size(), tmp, b, [](const Edge& e) { return e.v; });
    radix_sort(v.data(), v.size(), tmp, b, [](const Edge& e) { return e.u; });
  }
}

template <class L>
std::string Engine<L>::make_tmpdir() {
  if (!tmp_) {
    tmp_.emplace(tmp_parent_, "tetstream-verify");
    spdlog::debug("verify: spilling to {}", tmp_->dir());
  }
  return tmp_->dir();
}

template <class L>
void Engine<L>::plan_memory() {
  const std::size_t points = std::size_t(n_) * 24 + used_.bytes() + hull_used_.bytes();
  // A frame: two label buffers (one decoding) and flags. A step, per tet: the slices'
  // A, B, merged and radix buffers (11 facets, 15 edges), the merged copy (4 facets,
  // 6 edges) and up to 2 pair checks.
  std::size_t max_frame = 0;
  for (std::size_t k = 0; k < src_.batch_count(); ++k)
    max_frame = std::max<std::size_t>(max_frame, std::size_t(src_.batch(k).tet_count));
  const std::size_t step = std::min<std::size_t>(max_frame, opt_.batch_tets);
  const std::size_t scratch = max_frame * (2 * 4 * sizeof(L) + 1) +
                              step * (15 * sizeof(Facet) + 21 * sizeof(Edge) + 2 * sizeof(PairCheck));
  const std::size_t fixed = points + scratch;
  std::size_t rest = opt_.memory_bytes > fixed ? std::size_t(opt_.memory_bytes - fixed) : 0;
  if (rest < (std::size_t(16) << 20)) {
    spdlog::warn("verify: --memory {} is below what the points and one batch need ({}); going over it",
                 human_bytes(double(opt_.memory_bytes)), human_bytes(double(fixed)));
    rest = std::size_t(16) << 20;
  }
  // During the pass: the open sets, each with a merged copy of the same size (3/8 +
  // 1/8 of the rest, doubled). After it, the open sets are gone and one spill merges
  // at a time (5/8), while the boundary-edge sort may hold its buffer (1/8) and the
  // merged facets wait to be folded (1/8).
  live_facet_budget_ = rest * 3 / 16;
  live_edge_budget_ = rest / 16;
  if (opt_.open_bytes) live_facet_budget_ = opt_.open_bytes, live_edge_budget_ = opt_.open_bytes / 3;
  sorter_budget_ = rest * 5 / 8;
  rep_.memory_planned = fixed + rest;
  spdlog::debug("verify: memory: points {}, scratch {}, open facets {}, open edges {}, sorts {}",
                human_bytes(double(points)), human_bytes(double(scratch)), human_bytes(double(live_facet_budget_)),
                human_bytes(double(live_edge_budget_)), human_bytes(double(sorter_budget_)));
}

template <class L>
void Engine<L>::load_points() {
  const auto t0 = Clock::now();
  xyz_.resize(3 * std::size_t(n_));
  constexpr std::uint64_t kChunk = 1 << 20;
  const std::int64_t chunks = std::int64_t((n_ + kChunk - 1) / kChunk);
  std::exception_ptr error;
  std::mutex error_mutex;
#pragma omp parallel for schedule(dynamic, 1)
  for (std::int64_t c = 0; c < chunks; ++c) {
    const std::uint64_t first = std::uint64_t(c) * kChunk;
    try {
      src_.read_points(first, std::size_t(std::min(kChunk, n_ - first)), xyz_.data() + 3 * first);
    } catch (...) {
      std::lock_guard<std::mutex> lock(error_mutex);
      if (!error) error = std::current_exception();
    }
  }
  if (error) std::rethrow_exception(error);
  // The lexicographically smallest point is a vertex of the convex hull: the cones
  // from it over the hull facets have non-negative volume (no cancellation).
  std::uint64_t best = 0;
  for (std::uint64_t i = 1; i < n_; ++i) {
    const double* p = P(i);
    const double* b = P(best);
    if (p[0] < b[0] || (p[0] == b[0] && (p[1] < b[1] || (p[1] == b[1] && p[2] < b[2])))) best = i;
  }
  if (n_ > 0) std::copy(P(best), P(best) + 3, origin_);
  wide_volume_ = !volume_fits_double(xyz_.data(), std::size_t(n_));
  seconds_points_ = since(t0);
}

template <class L>
void Engine<L>::run() {
  const auto t0 = Clock::now();
  tmp_parent_ = opt_.tmpdir;
  if (tmp_parent_.empty()) {
    const char* env = std::getenv("TMPDIR");
    tmp_parent_ = env && *env ? std::string(env) : src_.directory();
    if (tmp_parent_.empty()) tmp_parent_ = ".";
  }
  plan_memory();
  load_points();

  auto make_dir = [this] { return make_tmpdir(); };
  {
    ExternalSortOptions o;
    o.memory_bytes = sorter_budget_;
    o.make_dir = make_dir;
    o.name = "facets";
    facet_spill_ = std::make_unique<ExternalSorter<Facet, FacetLess<L>>>(o);
    o.name = "edges";
    edge_spill_ = std::make_unique<ExternalSorter<Edge, std::less<Edge>>>(o);
    edge_spill_->set_reducer([](Edge* first, std::size_t n) { return std::size_t(std::unique(first, first + n) - first); });
    o.name = "hull-edges";
    o.memory_bytes = std::max<std::size_t>(sorter_budget_ / 5, std::size_t(4) << 20);
    hull_sorter_ = std::make_unique<ExternalSorter<HullEdge, HullEdgeLess<L>>>(o);
  }

  // Pass over the tets, frame by frame in order of their smallest label (frames
  // are independent, so any order is allowed, and this one retires keys soonest even
  // when a writer appended a late frame); the next frame decodes while this one is
  // checked. later_min[j]: the smallest label of the frames after position j.
  const auto t1 = Clock::now();
  const std::size_t frames = src_.batch_count();
  std::vector<std::size_t> order(frames);
  std::iota(order.begin(), order.end(), std::size_t(0));
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return src_.batch(a).min_label < src_.batch(b).min_label; });
  std::vector<std::uint64_t> later_min(frames + 1, ~0ull);
  for (std::size_t j = frames; j-- > 0;) later_min[j] = std::min(later_min[j + 1], src_.batch(order[j]).min_label);
  Progress progress("verifying", "tets", src_.tet_count(), opt_.progress);
  std::vector<L> current, next;
  std::future<void> pending;
  if (frames > 0) pending = std::async(std::launch::async, [&] { src_.read_batch(order[0], next); });
  for (std::size_t j = 0; j < frames; ++j) {
    pending.get();
    std::swap(current, next);
    if (j + 1 < frames) pending = std::async(std::launch::async, [&, j] { src_.read_batch(order[j + 1], next); });
    try {
      process_frame(order[j], current, later_min[j + 1]);
    } catch (...) {
      if (pending.valid()) pending.wait();
      throw;
    }
    progress.add(current.size() / 4);
    check_interrupted();
  }
  progress.finish();
  current = {}, next = {};
  seconds_tets_ = since(t1);

  // Everything still open is final now (or goes to the spills): free the open sets
  // before the spills merge.
  const auto t2 = Clock::now();
  if (!sampled_) merge_edges(~0ull);
  live_e_ = {}, merged_e_ = {};
  retire_facets(~0ull);
  live_ = {}, merged_ = {}, parts_ = {};
  finish_facets();
  if (!sampled_) {
    finish_hull();
    finish_edges();
  }
  seconds_final_ = since(t2);
  finish();
  rep_.seconds = since(t0);
  spdlog::debug("verify: points {:.2f}s, tets {:.2f}s, final merges {:.2f}s", seconds_points_, seconds_tets_,
                seconds_final_);
}

// One frame: storage, orientation and volume of every tet, then its facets and edges
// in steps of batch_tets tets.
template <class L>
void Engine<L>::process_frame(std::size_t k, std::vector<L>& labels, std::uint64_t future_min) {
  const VerifySource::Batch b = src_.batch(k);
  const std::size_t t = labels.size() / 4;
  if (labels.size() % 4 != 0 || t != b.tet_count)
    throw InputError(src_.name() + ": frame " + std::to_string(k) + ": " + std::to_string(labels.size() / 4) +
                     " tets decoded, " + std::to_string(b.tet_count) + " expected");
  // Canonical form in place: the labels sorted; flags bit 0: odd permutation (the
  // sorted order has the opposite orientation), bit 1: broken (storage).
  std::vector<std::uint8_t> flags(t);
  constexpr std::size_t kChunk = 4096;  // fixed chunks: volume sums independent of threads
  const std::int64_t chunks = std::int64_t((t + kChunk - 1) / kChunk);
  std::vector<long double> vol(std::size_t(chunks), 0.0L);
  std::uint64_t checked = 0, good = 0;
  bool below_min = false;
#pragma omp parallel for schedule(dynamic, 4) reduction(+ : checked, good) reduction(|| : below_min)
  for (std::int64_t c = 0; c < chunks; ++c) {
    const std::size_t lo = std::size_t(c) * kChunk, hi = std::min(t, lo + kChunk);
    long double sum = 0;
    for (std::size_t i = lo; i < hi; ++i) {
      L* v = labels.data() + 4 * i;
      const std::uint64_t ordinal = b.first_tet + i;
      const L g[4] = {v[0], v[1], v[2], v[3]};
      bool ok = g[0] < n_ && g[1] < n_ && g[2] < n_ && g[3] < n_;
      // Sort the four labels (5 compare-exchanges), counting swaps for the parity.
      int swaps = 0;
      auto cx = [&](int a, int bb) {
        if (v[a] > v[bb]) std::swap(v[a], v[bb]), ++swaps;
      };
      cx(0, 1), cx(2, 3), cx(0, 2), cx(1, 3), cx(1, 2);
      if (v[0] == v[1] || v[1] == v[2] || v[2] == v[3]) ok = false;
      std::uint8_t f = std::uint8_t(swaps & 1);
      if (!ok) {
        f |= 2;
        log_.add(Violation::kStorage, ordinal, [&] {
          return tet_text(ordinal, g[0], g[1], g[2], g[3]) + ": labels must be distinct and below " + std::to_string(n_);
        });
        flags[i] = f;
        continue;
      }
      ++good;
      if (std::uint64_t(v[0]) < b.min_label) below_min = true;
      for (int j = 0; j < 4; ++j) used_.set(v[j]);
      const double *p0 = P(g[0]), *p1 = P(g[1]), *p2 = P(g[2]), *p3 = P(g[3]);
      sum += std::fabs(volume6(p0, p1, p2, p3));
      if (tet_sampled(ordinal)) {
        ++checked;
        const int o = core::orient3d(p0, p1, p2, p3);
        if (o <= 0)
          log_.add(Violation::kOrientation, ordinal, [&] {
            return tet_text(ordinal, g[0], g[1], g[2], g[3]) +
                   (o == 0 ? ": flat (orient3d = 0)" : ": negatively oriented (orient3d = -1)");
          });
      }
      flags[i] = f;
    }
    vol[std::size_t(c)] = sum;
  }
  if (below_min)
    throw InputError(src_.name() + ": frame " + std::to_string(k) + ": a label below the frame's declared smallest label " +
                     std::to_string(b.min_label));
  for (long double s : vol) tet_volume6_ += s;
  tets_checked_ += checked;
  good_tets_ += good;
  orient_tests_ += checked;

  // Steps: after each, keys below the smallest label still to come (in later steps
  // of this frame or in later frames) are final.
  const std::size_t step = opt_.batch_tets;
  const std::size_t steps = (t + step - 1) / step;
  std::vector<std::uint64_t> later_min(steps + 1, future_min);
  for (std::size_t s = steps; s-- > 0;) {
    std::uint64_t m = later_min[s + 1];
    for (std::size_t i = s * step, hi = std::min(t, (s + 1) * step); i < hi; ++i)
      if (!(flags[i] & 2)) m = std::min<std::uint64_t>(m, labels[4 * i]);
    later_min[s] = m;
  }
  for (std::size_t s = 0; s < steps; ++s) {
    const std::size_t lo = s * step, hi = std::min(t, lo + step);
    bool sorted = true;
    for (std::size_t i = lo + 1; i < hi && sorted; ++i) sorted = labels[4 * i] >= labels[4 * (i - 1)];
    process_step(labels.data() + 4 * lo, flags.data() + lo, hi - lo, b.first_tet + lo, sorted, later_min[s + 1]);
  }
}

// Facets and edges of `count` canonical tets; then retire what no later tet can touch.
// Two parallel regions: each thread builds the sorted records of a slice of the tets;
// then each thread merges one key range of all slices and the open set, folds it and
// runs the insphere tests of the pairs it formed.
template <class L>
void Engine<L>::process_step(const L* canon, const std::uint8_t* flags, std::size_t count,
                             std::uint64_t first_ordinal, bool sorted_by_min, std::uint64_t threshold) {
  const int threads = count >= 8192 ? std::max(1, omp_get_max_threads()) : 1;
  if (parts_.size() < std::size_t(threads)) parts_.resize(std::size_t(threads));
#pragma omp parallel for num_threads(threads) schedule(static, 1) if (threads > 1)
  for (int p = 0; p < threads; ++p) {
    const std::size_t lo = count * std::size_t(p) / std::size_t(threads);
    const std::size_t hi = count * (std::size_t(p) + 1) / std::size_t(threads);
    build_part(parts_[std::size_t(p)], canon, flags, lo, hi, first_ordinal, sorted_by_min);
  }

  // ---- facets: merge the slices with the open set (open first on equal keys), fold.
  if (chunk_checks_.size() < std::size_t(std::max(1, omp_get_max_threads())))
    chunk_checks_.resize(std::size_t(std::max(1, omp_get_max_threads())));
  {
    std::vector<std::span<const Facet>> in;
    in.emplace_back(live_);
    for (int p = 0; p < threads; ++p) {
      in.emplace_back(parts_[std::size_t(p)].f);
      facets_checked_ += parts_[std::size_t(p)].f.size();
    }
    const FacetLess<L> less;
    auto key_less = [](const Facet& a, const Facet& b) {
      if (a.v[0] != b.v[0]) return a.v[0] < b.v[0];
      if (a.v[1] != b.v[1]) return a.v[1] < b.v[1];
      return a.v[2] < b.v[2];
    };
    const std::size_t n = merge_ranges(
        in, merged_, less, key_less, chunk_sizes_, [&](std::size_t r, Facet* first, std::size_t m) {
          auto& cc = chunk_checks_[r];
          cc.clear();
          const std::size_t w = fold_equal_keys(first, m, cc);
          check_pairs(cc);
          return w;
        });
    merged_.resize(n);
    std::swap(live_, merged_);
    retire_facets(threshold);
  }

  // ---- edges (not in a sample): union of the slices and the open set.
  if (!sampled_) {
    std::vector<std::span<const Edge>> in;
    in.emplace_back(live_e_);
    for (int p = 0; p < threads; ++p) in.emplace_back(parts_[std::size_t(p)].e);
    const std::less<Edge> less;
    const std::size_t n = merge_ranges(in, merged_e_, less, less, chunk_sizes_, [](std::size_t, Edge* first, std::size_t m) {
      return std::size_t(std::unique(first, first + m) - first);
    });
    merged_e_.resize(n);
    std::swap(live_e_, merged_e_);
    merge_edges(threshold);
  }
}

// The sorted facet and edge records of tets [lo, hi) of a step, on one thread.
// A = the three facets (edges) through the tet's smallest label, B = the rest. Facet
// opposite s_i, written (others sorted, s_i), has the orientation of (s0..s3) times
// (-1)^(3-i), and (s0..s3) has the tet's times (-1)^parity.
template <class L>
void Engine<L>::build_part(Part& part, const L* canon, const std::uint8_t* flags, std::size_t lo, std::size_t hi,
                           std::uint64_t first_ordinal, bool sorted_by_min) {
  auto& a = part.a;
  auto& b = part.b;
  a.clear(), b.clear();
  a.reserve(3 * (hi - lo)), b.reserve(hi - lo);
  for (std::size_t i = lo; i < hi; ++i) {
    if (flags[i] & 2) continue;  // broken: no facets
    const L* s = canon + 4 * i;
    const std::uint64_t ordinal = first_ordinal + i;
    const int parity = flags[i] & 1;
    auto side = [&](int opp) { return ((parity + 3 - opp) & 1) == 0 ? kSide : 0; };
    if (facet_sampled(s[0], s[1], s[2])) a.push_back(Facet{{s[0], s[1], s[2]}, s[3], ordinal | side(3)});
    if (facet_sampled(s[0], s[1], s[3])) a.push_back(Facet{{s[0], s[1], s[3]}, s[2], ordinal | side(2)});
    if (facet_sampled(s[0], s[2], s[3])) a.push_back(Facet{{s[0], s[2], s[3]}, s[1], ordinal | side(1)});
    if (facet_sampled(s[1], s[2], s[3])) b.push_back(Facet{{s[1], s[2], s[3]}, s[0], ordinal | side(0)});
  }
  const FacetLess<L> less;
  if (sorted_by_min) {
    // A is grouped by smallest label already: sort each group (a lower star).
    for (std::size_t g = 0; g < a.size();) {
      std::size_t e = g + 1;
      while (e < a.size() && a[e].v[0] == a[g].v[0]) ++e;
      std::sort(a.begin() + std::ptrdiff_t(g), a.begin() + std::ptrdiff_t(e), less);
      g = e;
    }
  } else {
    sort_facets(a, part.tmp);
  }
  sort_facets(b, part.tmp);
  part.f.resize(a.size() + b.size());
  std::merge(a.begin(), a.end(), b.begin(), b.end(), part.f.begin(), less);

  if (sampled_) return;
  auto& ea = part.ea;
  auto& eb = part.eb;
  ea.clear(), eb.clear();
  ea.reserve(3 * (hi - lo)), eb.reserve(3 * (hi - lo));
  for (std::size_t i = lo; i < hi; ++i) {
    if (flags[i] & 2) continue;
    const L* s = canon + 4 * i;
    ea.push_back(make_edge(s[0], s[1])), ea.push_back(make_edge(s[0], s[2])), ea.push_back(make_edge(s[0], s[3]));
    eb.push_back(make_edge(s[1], s[2])), eb.push_back(make_edge(s[1], s[3])), eb.push_back(make_edge(s[2], s[3]));
  }
  if (sorted_by_min) {
    for (std::size_t g = 0; g < ea.size();) {
      std::size_t e = g + 1;
      while (e < ea.size() && edge_u(ea[e]) == edge_u(ea[g])) ++e;
      std::sort(ea.begin() + std::ptrdiff_t(g), ea.begin() + std::ptrdiff_t(e));
      g = e;
    }
  } else {
    sort_edges(ea, part.etmp);
  }
  sort_edges(eb, part.etmp);
  ea.erase(std::unique(ea.begin(), ea.end()), ea.end());
  eb.erase(std::unique(eb.begin(), eb.end()), eb.end());
  part.e.resize(ea.size() + eb.size());
  part.e.erase(std::set_union(ea.begin(), ea.end(), eb.begin(), eb.end(), part.e.begin()), part.e.end());
}

template <class L>
std::size_t Engine<L>::fold_equal_keys(Facet* first, std::size_t n, std::vector<PairCheck>& checks) {
  std::size_t w = 0, g = 0;
  while (g < n) {
    Facet s = first[g];
    std::size_t e = g + 1;
    for (; e < n && same_key(first[e], s); ++e) combine(s, first[e], checks);
    first[w++] = s;
    g = e;
  }
  return w;
}

// Folds runs of records with equal keys (sorted input) in place; returns the new size.
template <class L>
std::size_t Engine<L>::fold(Facet* first, Facet* last) {
  const std::size_t n = std::size_t(last - first);
  const int parts_hint = chunk_count(n);
  chunk_checks_.resize(std::size_t(parts_hint));
  chunk_sizes_.assign(std::size_t(parts_hint), 0);
  for_group_chunks(
      n, [&](std::size_t i) { return i == 0 || !same_key(first[i], first[i - 1]); },
      [&](std::size_t p, std::size_t lo, std::size_t hi) {
        auto& cc = chunk_checks_[p];
        cc.clear();
        chunk_sizes_[p] = fold_equal_keys(first + lo, hi - lo, cc);
      },
      bounds_);
  // Close the gaps between the compacted chunks.
  std::size_t w = 0;
  for (std::size_t p = 0; p + 1 < bounds_.size(); ++p) {
    const std::size_t lo = bounds_[p], m = chunk_sizes_[p];
    if (w != lo && m) std::memmove(static_cast<void*>(first + w), first + lo, m * sizeof(Facet));
    w += m;
  }
  return w;
}

// s := s combined with r (same key). See FacetRec for the states.
template <class L>
void Engine<L>::combine(Facet& s, const Facet& r, std::vector<PairCheck>& checks) {
  if (s.x & kBad) return;
  if (r.x & kBad) {
    s = r;
    return;
  }
  const bool sp = (s.x & kPair) != 0, rp = (r.x & kPair) != 0;
  if (!sp && !rp) {
    const bool ss = (s.x & kSide) != 0, rs = (r.x & kSide) != 0;
    const std::uint64_t ts = s.x & kPayload, tr = r.x & kPayload;
    if (ss != rs && s.d != r.d) {
      const L dpos = ss ? s.d : r.d, dneg = ss ? r.d : s.d;
      checks.push_back(PairCheck{{s.v[0], s.v[1], s.v[2]}, dpos, dneg, ss ? ts : tr, ss ? tr : ts});
      s.d = dpos;
      s.x = kPair | std::uint64_t(dneg);
      return;
    }
    if (s.d == r.d) {
      // The same four labels twice; reported once, at the facet opposite the largest.
      if (s.d > s.v[2])
        log_.add(Violation::kDuplicateTet, std::max(ts, tr), [&] {
          return "tet #" + std::to_string(std::max(ts, tr)) + " " + labels_text({s.v[0], s.v[1], s.v[2], s.d}) +
                 " repeats tet #" + std::to_string(std::min(ts, tr)) +
                 (ss != rs ? " with the opposite orientation" : "");
        });
    } else {
      log_.add(Violation::kFacetSameSide, std::min(ts, tr), [&] {
        return "tets #" + std::to_string(ts) + " " + labels_text({s.v[0], s.v[1], s.v[2], s.d}) + " and #" +
               std::to_string(tr) + " " + labels_text({s.v[0], s.v[1], s.v[2], r.d}) +
               " lie on the same side of their " + facet_text(s) + " (they overlap)";
      });
    }
    s.x = kBad | std::min(ts, tr);
    return;
  }
  if (sp && rp) {
    log_.add(Violation::kFacetOverused, 0, [&] {
      return facet_text(s) + " is in four or more tets (opposite vertices " + std::to_string(s.d) + ", " +
             std::to_string(s.x & kPayload) + ", " + std::to_string(r.d) + ", " + std::to_string(r.x & kPayload) + ")";
    });
    s.x = kBad;
    return;
  }
  const Facet& p = sp ? s : r;
  const Facet& q = sp ? r : s;  // the single
  const std::uint64_t dpos = p.d, dneg = p.x & kPayload, tq = q.x & kPayload;
  const bool qs = (q.x & kSide) != 0;
  const Facet key = s;
  if (q.d == dpos || q.d == dneg) {
    if (q.d > key.v[2])
      log_.add(Violation::kDuplicateTet, tq, [&] {
        return "tet #" + std::to_string(tq) + " " + labels_text({key.v[0], key.v[1], key.v[2], q.d}) +
               " repeats another tet" + ((qs == (q.d == dpos)) ? "" : " with the opposite orientation");
      });
  } else {
    log_.add(Violation::kFacetOverused, tq, [&] {
      return facet_text(key) + " is in three or more tets: tet #" + std::to_string(tq) + " " +
             labels_text({key.v[0], key.v[1], key.v[2], q.d}) + " and two tets with opposite vertices " +
             std::to_string(dpos) + " and " + std::to_string(dneg);
    });
  }
  s.x = kBad | tq;
}

// The local Delaunay test of each newly paired facet, in parallel.
template <class L>
void Engine<L>::check_pairs() {
  std::uint64_t n = 0;
  for (const auto& part : chunk_checks_) n += part.size();
  const std::int64_t parts = std::int64_t(chunk_checks_.size());
#pragma omp parallel for schedule(dynamic, 1) if (n > 8192)
  for (std::int64_t p = 0; p < parts; ++p) check_pairs(chunk_checks_[std::size_t(p)]);
}

template <class L>
void Engine<L>::check_pairs(const std::vector<PairCheck>& checks) {
  for (const PairCheck& c : checks) {
    const int s = core::insphere_sos(P(c.v[0]), P(c.v[1]), P(c.v[2]), P(c.dpos), P(c.dneg), c.v[0], c.v[1], c.v[2],
                                     c.dpos, c.dneg);
    if (s > 0)
      log_.add(Violation::kDelaunay, std::min(c.tpos, c.tneg), [&] {
        return "facet " + labels_text({c.v[0], c.v[1], c.v[2]}) + " of tets #" + std::to_string(c.tpos) + " and #" +
               std::to_string(c.tneg) + ": vertex " + std::to_string(c.dneg) + " lies inside the circumsphere of " +
               tet_text(c.tpos, c.v[0], c.v[1], c.v[2], c.dpos);
      });
  }
  insphere_tests_ += checks.size();
}

// Facets whose smallest label is below `threshold` are final (or go to the spill if a
// spilled run may hold the same key); the rest stay open, spilled when too many.
template <class L>
void Engine<L>::retire_facets(std::uint64_t threshold) {
  const auto cut = std::partition_point(live_.begin(), live_.end(),
                                        [&](const Facet& f) { return std::uint64_t(f.v[0]) < threshold; });
  const auto spill_from = std::partition_point(live_.begin(), cut,
                                               [&](const Facet& f) { return std::uint64_t(f.v[0]) < facet_spill_min_; });
  for (auto it = live_.begin(); it != spill_from; ++it) final_facet(*it);
  if (spill_from != cut) facet_spill_->push_sorted_run(std::span<Facet>(&*spill_from, std::size_t(cut - spill_from)));
  live_.erase(live_.begin(), cut);
  rep_.peak_open_facets = std::max<std::uint64_t>(rep_.peak_open_facets, live_.size());
  if (live_.size() * sizeof(Facet) > live_facet_budget_) {
    facet_spill_min_ = std::min<std::uint64_t>(facet_spill_min_, live_.front().v[0]);
    facet_spill_->push_sorted_run(std::span<Facet>(live_));
    live_.clear();
    live_.shrink_to_fit();
  }
  if (!hull_edges_batch_.empty()) {
    hull_sorter_->push(std::span<const HullEdge>(hull_edges_batch_));
    hull_edges_batch_.clear();
  }
}

// A facet with its final state.
template <class L>
void Engine<L>::final_facet(const Facet& f) {
  if (f.x & kPair) {
    ++interior_;
    return;
  }
  if (f.x & kBad) {
    ++bad_facets_;
    return;
  }
  ++boundary_;
  if (sampled_) return;  // unpaired in the sample: nothing more to say
  // A boundary facet, oriented outwards: its tet's fourth vertex on the negative side.
  L a = f.v[0], b = f.v[1], c = f.v[2];
  if (f.x & kSide) std::swap(b, c);
  hull_used_.set(a), hull_used_.set(b), hull_used_.set(c);
  hull_volume6_ += volume6(origin_, P(a), P(b), P(c));
  const std::uint64_t ord = f.x & kPayload;
  auto edge = [&](L p, L q, L w) {
    hull_edges_batch_.push_back(p < q ? HullEdge{p, q, w, ord | kSide} : HullEdge{q, p, w, ord});
  };
  edge(a, b, c), edge(b, c, a), edge(c, a, b);
}

template <class L>
void Engine<L>::merge_edges(std::uint64_t threshold) {
  const auto cut = std::partition_point(live_e_.begin(), live_e_.end(),
                                        [&](const Edge& e) { return edge_u(e) < threshold; });
  const auto spill_from = std::partition_point(live_e_.begin(), cut,
                                               [&](const Edge& e) { return edge_u(e) < edge_spill_min_; });
  edges_ += std::uint64_t(spill_from - live_e_.begin());
  if (spill_from != cut) edge_spill_->push_sorted_run(std::span<Edge>(&*spill_from, std::size_t(cut - spill_from)));
  live_e_.erase(live_e_.begin(), cut);
  rep_.peak_open_edges = std::max<std::uint64_t>(rep_.peak_open_edges, live_e_.size());
  if (live_e_.size() * sizeof(Edge) > live_edge_budget_) {
    edge_spill_min_ = std::min<std::uint64_t>(edge_spill_min_, edge_u(live_e_.front()));
    edge_spill_->push_sorted_run(std::span<Edge>(live_e_));
    live_e_.clear();
    live_e_.shrink_to_fit();
  }
}

// Everything still open is final now; spilled runs are merged with it.
template <class L>
void Engine<L>::finish_facets() {
  if (facet_spill_->records_pushed() == 0) return;
  // Groups may straddle merge batches: the tail group waits for the next batch.
  std::vector<Facet> pending;
  std::vector<Facet> group_out;
  auto flush = [&](bool last) {
    // Fold everything but the last group (unless last), then finalize it.
    std::size_t end = pending.size();
    if (!last) {
      while (end > 0 && same_key(pending[end - 1], pending.back())) --end;
      if (end == 0) return;
    }
    const std::size_t n = fold(pending.data(), pending.data() + end);
    check_pairs();
    for (std::size_t i = 0; i < n; ++i) final_facet(pending[i]);
    pending.erase(pending.begin(), pending.begin() + std::ptrdiff_t(end));
    if (!hull_edges_batch_.empty()) {
      hull_sorter_->push(std::span<const HullEdge>(hull_edges_batch_));
      hull_edges_batch_.clear();
    }
  };
  const std::size_t chunk = std::max<std::size_t>(sorter_budget_ / 5 / sizeof(Facet), 1 << 16);
  facet_spill_->merge([&](std::span<const Facet> batch) {
    pending.insert(pending.end(), batch.begin(), batch.end());
    if (pending.size() >= chunk) flush(false);
  });
  flush(true);
  rep_.spilled_records += facet_spill_->stats().records_pushed;
  rep_.spill_bytes += facet_spill_->stats().bytes_written;
  facet_spill_.reset();
}

template <class L>
void Engine<L>::finish_edges() {
  if (edge_spill_->records_pushed() == 0) return;
  bool have = false;
  Edge last{};
  edge_spill_->merge([&](std::span<const Edge> batch) {
    for (const Edge& e : batch) {
      if (have && e == last) continue;
      ++edges_;
      last = e;
      have = true;
    }
  });
  rep_.spilled_records += edge_spill_->stats().records_pushed;
  rep_.spill_bytes += edge_spill_->stats().bytes_written;
  edge_spill_.reset();
}

// The boundary surface: closed (each edge in two facets of opposite directions) and
// locally convex at every edge.
template <class L>
void Engine<L>::finish_hull() {
  struct Job {
    HullEdge first, second;  // first runs u -> v
  };
  std::vector<Job> jobs;
  std::vector<HullEdge> group;
  auto run_jobs = [&] {
    const std::int64_t n = std::int64_t(jobs.size());
#pragma omp parallel for schedule(dynamic, 1024) if (n > 4096)
    for (std::int64_t i = 0; i < n; ++i) {
      const Job& j = jobs[std::size_t(i)];
      const L u = j.first.u, v = j.first.v, w1 = j.first.w, w2 = j.second.w;
      const int s1 = core::infinite_conflict_sos(P(u), P(v), P(w1), P(w2), u, v, w1, w2);
      const int s2 = core::infinite_conflict_sos(P(v), P(u), P(w2), P(w1), v, u, w2, w1);
      if (s1 > 0 || s2 > 0) {
        const std::uint64_t t1 = j.first.x & kPayload, t2 = j.second.x & kPayload;
        log_.add(Violation::kHullConvex, std::min(t1, t2), [&] {
          const int o = core::orient3d(P(u), P(v), P(w1), P(w2));
          return "boundary edge " + labels_text({u, v}) + " of tets #" + std::to_string(t1) + " and #" +
                 std::to_string(t2) + ": facet " + labels_text({v, u, w2}) +
                 (o > 0 ? " bends inwards (reflex edge: a missing tet or a hole)"
                        : " is coplanar with facet " + labels_text({u, v, w1}) + " but not perturbed-Delaunay");
        });
      }
    }
    hull_tests_ += 2 * std::uint64_t(n);
    jobs.clear();
  };
  auto close_group = [&] {
    if (group.empty()) return;
    ++hull_edges_;
    const bool ok = group.size() == 2 && ((group[0].x & kSide) != (group[1].x & kSide)) && group[0].w != group[1].w;
    if (ok) {
      const bool first_fwd = (group[0].x & kSide) != 0;
      jobs.push_back(first_fwd ? Job{group[0], group[1]} : Job{group[1], group[0]});
      if (jobs.size() >= (1u << 16)) run_jobs();
    } else {
      std::uint64_t where = ~0ull;
      for (const HullEdge& h : group) where = std::min(where, h.x & kPayload);
      log_.add(Violation::kHullOpen, where, [&] {
        std::string s = "boundary edge " + labels_text({group[0].u, group[0].v}) + " is in " +
                        std::to_string(group.size()) + " boundary facet(s):";
        for (const HullEdge& h : group)
          s += " tet #" + std::to_string(h.x & kPayload) + " (third vertex " + std::to_string(h.w) +
               ((h.x & kSide) ? ", forward)" : ", backward)");
        return s;
      });
    }
    group.clear();
  };
  hull_sorter_->merge([&](std::span<const HullEdge> batch) {
    for (const HullEdge& h : batch) {
      if (!group.empty() && (group[0].u != h.u || group[0].v != h.v)) close_group();
      group.push_back(h);
    }
  });
  close_group();
  run_jobs();
  rep_.spilled_records += hull_sorter_->stats().runs_written ? hull_sorter_->stats().records_pushed : 0;
  rep_.spill_bytes += hull_sorter_->stats().bytes_written;
  hull_sorter_.reset();
}

template <class L>
void Engine<L>::finish() {
  VerifyReport& r = rep_;
  r.sampled = sampled_;
  r.sample = opt_.sample;
  r.points = n_;
  r.tets = src_.tet_count();
  r.vertices = used_.count();
  r.interior_facets = interior_;
  r.boundary_facets = boundary_;
  r.facets = interior_ + boundary_ + bad_facets_;
  r.orient_tests = orient_tests_.load();
  r.insphere_tests = insphere_tests_.load();
  r.hull_tests = hull_tests_.load();
  r.tets_checked = tets_checked_;
  r.facets_checked = facets_checked_;

  // Coverage: every label a vertex.
  if (r.vertices < n_) {
    for (std::uint64_t l = 0; l < n_; ++l)
      if (!used_.get(l))
        log_.add(Violation::kMissingPoint, l, [&] {
          const double* p = P(l);
          return "point " + std::to_string(l) + " (" + std::to_string(p[0]) + ", " + std::to_string(p[1]) + ", " +
                 std::to_string(p[2]) + ") is in no tet";
        });
  }
  if (!sampled_) {
    r.edges = edges_;
    r.hull_vertices = hull_used_.count();
    r.hull_edges = hull_edges_;
    r.euler = std::int64_t(r.vertices) - std::int64_t(r.edges) + std::int64_t(r.facets) - std::int64_t(good_tets_);
    r.hull_euler = std::int64_t(r.hull_vertices) - std::int64_t(r.hull_edges) + std::int64_t(r.boundary_facets);
    if (r.euler != 1)
      log_.add(Violation::kEuler, 0, [&] {
        return "V - E + F - T = " + std::to_string(r.vertices) + " - " + std::to_string(r.edges) + " + " +
               std::to_string(r.facets) + " - " + std::to_string(good_tets_) + " = " + std::to_string(r.euler) +
               ", not 1";
      });
    if (r.hull_euler != 2)
      log_.add(Violation::kHullTopology, 0, [&] {
        return "boundary V - E + F = " + std::to_string(r.hull_vertices) + " - " + std::to_string(r.hull_edges) +
               " + " + std::to_string(r.boundary_facets) + " = " + std::to_string(r.hull_euler) +
               ", not 2: the boundary is not one sphere (a cavity, a loose piece or a tunnel)";
      });
    // Compared in long double (the volumes of coordinates near DBL_MAX exceed any
    // double); reported as doubles (inf when they do).
    r.tet_volume = double(tet_volume6_ / 6);
    r.hull_volume = double(hull_volume6_ / 6);
    const long double scale = std::max(std::fabs(hull_volume6_), std::numeric_limits<long double>::min());
    r.volume_rel_error = double(std::fabs(tet_volume6_ - hull_volume6_) / scale);
    if (!(r.volume_rel_error <= opt_.volume_tolerance))
      log_.add(Violation::kVolume, 0, [&] {
        std::ostringstream s;
        s.precision(17);
        s << "tets fill " << r.tet_volume << ", the boundary encloses " << r.hull_volume << ": relative difference "
          << r.volume_rel_error << " > " << opt_.volume_tolerance;
        return s.str();
      });
  }
  log_.into(r);
}

}  // namespace

VerifyReport verify(const VerifySource& source, const VerifyOptions& options) {
  options.validate();
  VerifyReport report;
  if (source.point_count() <= 0xFFFFFFFFull && !options.wide_labels) {
    Engine<std::uint32_t> e(source, options, report);
    e.run();
  } else {
    Engine<std::uint64_t> e(source, options, report);
    e.run();
  }
  return report;
}

VerifyReport verify_file(const std::string& path, const VerifyOptions& options) {
  options.validate();
  io::TetReader reader(path);
  reader.verify_points();
  ContainerSource source(reader);
  return verify(source, options);
}

}  // namespace tetstream::pipeline
