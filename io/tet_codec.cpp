// The lower-star frame codec (docs/format.md §4). Read the spec first: the encoder and
// the decoder below are its two directions and share the context rules (§4.3).
#include "io/tet_codec.hpp"

#include "core/compiler.hpp"
#include "core/small_sort.hpp"
#include "io/tet_container.hpp"

#include <zstd.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cstring>
#include <limits>
#include <utility>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace tetstream::io {
namespace {

enum Stream : int { kHead = 0, kAbsent, kGapLo, kGapHi, kIndex, kParity };
const char* const kStreamName[kFrameStreams] = {"HEAD", "ABSN", "GLO", "GHI", "IDX", "PAR"};

constexpr int kMaxCtxLog2 = 16;
constexpr unsigned kSlotCapacity = 14;
constexpr std::uint64_t kMaxOffset = 65535;
// Decoded streams are followed by this many zero bytes, so the decoder can read a
// whole group or tet before checking its stream pointers against the ends.
constexpr std::size_t kStreamPadding = 64;

// ---------------------------------------------------------------- context (§4.3)

// One slot: e[0] is the count n, e[1..n] the offsets (a set, at most 14), e[15]
// scratch. insert() stores the offset at e[1 + n] unconditionally and bumps n only
// when it was new: a lane past n then holds a value that is already in the set (or, in
// the scratch lane of a full slot, one that can no longer be added), so the SIMD
// membership test over all 15 lanes gives exactly the set semantics of the spec.
struct alignas(32) Slot {
  std::uint16_t e[16];
};

class Context {
 public:
  void reset(int log2) {
    const std::size_t r = std::size_t(1) << log2;
    if (slots_.size() < r) slots_.resize(r);
    std::memset(static_cast<void*>(slots_.data()), 0, r * sizeof(Slot));
    mask_ = r - 1;
  }

  // Step 1 of §4.3: empty the slots of the labels skipped between two groups.
  void advance(std::uint64_t prev_m, std::uint64_t m) {
    if (m - prev_m > mask_) {
      std::memset(static_cast<void*>(slots_.data()), 0, (mask_ + 1) * sizeof(Slot));
    } else {
      for (std::uint64_t v = prev_m + 1; v < m; ++v) clear(slots_[v & mask_]);
    }
  }

  // Step 2: the offsets of K(m) from m, sorted, into off[0..n), and off[n..16) zeroed;
  // empties the slot.
  unsigned take(std::uint64_t m, std::uint16_t (&off)[16]) {
    Slot& s = slots_[m & mask_];
    const unsigned n = s.e[0];
    std::memset(off, 0, sizeof off);
#if defined(__SSE2__)
    // Rank sort: the rank of an offset is the number of offsets below it (they are
    // distinct). Lanes other than 1..n are set to 0xFFFF, which is below nothing;
    // comparisons are signed, hence the bias.
    const __m128i bias = _mm_set1_epi16(static_cast<short>(0x8000));
    const __m128i lane = _mm_setr_epi16(0, 1, 2, 3, 4, 5, 6, 7), eight = _mm_set1_epi16(8);
    const __m128i first = _mm_set1_epi16(1), last = _mm_set1_epi16(static_cast<short>(n));
    auto valid = [&](__m128i l) {  // 1 <= l <= n
      return _mm_andnot_si128(_mm_or_si128(_mm_cmplt_epi16(l, first), _mm_cmpgt_epi16(l, last)), _mm_set1_epi16(-1));
    };
    const __m128i v0 = valid(lane), v1 = valid(_mm_add_epi16(lane, eight));
    const __m128i e0 = _mm_load_si128(reinterpret_cast<const __m128i*>(s.e));
    const __m128i e1 = _mm_load_si128(reinterpret_cast<const __m128i*>(s.e + 8));
    const __m128i ones = _mm_set1_epi16(-1);
    const __m128i b0 = _mm_xor_si128(_mm_or_si128(_mm_and_si128(v0, e0), _mm_andnot_si128(v0, ones)), bias);
    const __m128i b1 = _mm_xor_si128(_mm_or_si128(_mm_and_si128(v1, e1), _mm_andnot_si128(v1, ones)), bias);
    for (unsigned i = 0; i < n; ++i) {
      const std::uint16_t x = s.e[1 + i];
      const __m128i key = _mm_set1_epi16(static_cast<short>(x ^ 0x8000));
      // One bit per lane below x; then count them (SWAR: no POPCNT in baseline x86-64).
      unsigned below = unsigned(_mm_movemask_epi8(_mm_packs_epi16(_mm_cmplt_epi16(b0, key), _mm_cmplt_epi16(b1, key))));
      below = below - ((below >> 1) & 0x5555u);
      below = (below & 0x3333u) + ((below >> 2) & 0x3333u);
      below = (below + (below >> 4)) & 0x0F0Fu;
      off[(below + (below >> 8)) & 0x1Fu] = x;
    }
#else
    for (unsigned i = 0; i < n; ++i) {
      const std::uint16_t x = s.e[1 + i];
      unsigned j = i;
      while (j > 0 && off[j - 1] > x) off[j] = off[j - 1], --j;
      off[j] = x;
    }
#endif
    clear(s);
    return n;
  }

  // Step 3 for one tet (m, a, lo, hi): insert (a, lo), (a, hi), (lo, hi). The first two
  // share a slot and are done together (lo != hi, so their membership tests against the
  // slot before either insertion are the sequential ones).
  TS_FORCE_INLINE void insert_tet(std::uint64_t m, std::uint64_t a, std::uint64_t lo, std::uint64_t hi) {
    if (a - m <= mask_) {
      Slot& s = slots_[a & mask_];
      if (hi - a <= kMaxOffset) {  // then lo - a is in range too
        const std::uint16_t o1 = static_cast<std::uint16_t>(lo - a), o2 = static_cast<std::uint16_t>(hi - a);
        const bool f1 = contains(s, o1), f2 = contains(s, o2);
        const unsigned n = s.e[0];
        s.e[1 + n] = o1;
        const unsigned n1 = n + unsigned(!f1 && n < kSlotCapacity);
        s.e[1 + n1] = o2;
        s.e[0] = static_cast<std::uint16_t>(n1 + unsigned(!f2 && n1 < kSlotCapacity));
      } else if (lo - a <= kMaxOffset) {
        add(s, static_cast<std::uint16_t>(lo - a));
      }
    }
    if (lo - m <= mask_ && hi - lo <= kMaxOffset) add(slots_[lo & mask_], static_cast<std::uint16_t>(hi - lo));
  }

  void prefetch(std::uint64_t m, std::uint64_t v) const {
    if (v - m <= mask_) TS_PREFETCH(&slots_[v & mask_]);
  }

 private:
  static void clear(Slot& s) { std::memset(static_cast<void*>(&s), 0, sizeof s); }

  // Whether offset o is in the slot (lanes 1..15, see Slot).
  static TS_FORCE_INLINE bool contains(const Slot& s, std::uint16_t o) {
#if defined(__SSE2__)
    const __m128i key = _mm_set1_epi16(static_cast<short>(o));
    const __m128i lo = _mm_load_si128(reinterpret_cast<const __m128i*>(s.e));
    const __m128i hi = _mm_load_si128(reinterpret_cast<const __m128i*>(s.e + 8));
    const unsigned hit = unsigned(_mm_movemask_epi8(_mm_cmpeq_epi16(lo, key))) |
                         unsigned(_mm_movemask_epi8(_mm_cmpeq_epi16(hi, key))) << 16;
    return (hit & ~3u) != 0;  // lane 0 is the count
#else
    bool found = false;
    for (unsigned i = 1; i < 16; ++i) found |= s.e[i] == o;
    return found;
#endif
  }
  static TS_FORCE_INLINE void add(Slot& s, std::uint16_t o) {
    const bool found = contains(s, o);
    const unsigned n = s.e[0];
    s.e[1 + n] = o;
    s.e[0] = static_cast<std::uint16_t>(n + unsigned(!found && n < kSlotCapacity));
  }

  std::vector<Slot> slots_;
  std::uint64_t mask_ = 0;
};

// The position of offset d (>= 1) among off[0..16) (zero-padded), or -1.
TS_FORCE_INLINE int find_offset(const std::uint16_t (&off)[16], std::uint16_t d) {
#if defined(__SSE2__)
  const __m128i key = _mm_set1_epi16(static_cast<short>(d));
  const unsigned hit =
      unsigned(_mm_movemask_epi8(_mm_cmpeq_epi16(_mm_load_si128(reinterpret_cast<const __m128i*>(off)), key))) |
      unsigned(_mm_movemask_epi8(_mm_cmpeq_epi16(_mm_load_si128(reinterpret_cast<const __m128i*>(off + 8)), key)))
          << 16;
  return hit ? std::countr_zero(hit) / 2 : -1;
#else
  for (int q = 0; q < 16; ++q) {
    if (off[q] == d) return q;
  }
  return -1;
#endif
}

constexpr std::uint8_t kNewLabel = 0xFF;
// A tet of a group packs into one sortable u64 as ia << 43 | il << 22 | ih << 1 | p
// when every position fits 21 bits.
constexpr std::uint64_t kMaxPackedPosition = (std::uint64_t(1) << 21) - 1;

int context_log2(std::uint64_t base, std::uint64_t max_label) {
  return std::min(kMaxCtxLog2, int(std::bit_width(max_label - base)));
}

// ---------------------------------------------------------------- byte helpers

inline void put_varint(std::vector<std::uint8_t>& out, std::uint64_t v) {
  while (v >= 0x80) {
    out.push_back(static_cast<std::uint8_t>(v | 0x80));
    v >>= 7;
  }
  out.push_back(static_cast<std::uint8_t>(v));
}

// Writes an escaped value (format.md §4.2) at p; returns the end. At most 11 bytes.
TS_FORCE_INLINE std::uint8_t* put_escaped(std::uint8_t* p, std::uint64_t v) {
  if (TS_LIKELY(v < 255)) {
    *p++ = static_cast<std::uint8_t>(v);
    return p;
  }
  *p++ = 255;
  v -= 255;
  while (v >= 0x80) *p++ = static_cast<std::uint8_t>(v | 0x80), v >>= 7;
  *p++ = static_cast<std::uint8_t>(v);
  return p;
}

template <class L>
struct Canon {
  L m, a, lo, hi;
  std::uint32_t p;
};

// §4.1: the labels sorted, m < a < lo < hi (if distinct), and the parity of the
// permutation that sorts them: 0 when (m, a, lo, hi) is an even rotation of t, so
// the canonical form is (m, a, lo, hi), else (m, a, hi, lo). A sorting network whose
// swaps are counted, without branches.
template <class L>
TS_FORCE_INLINE Canon<L> canonical(const L* t) {
  L v0 = t[0], v1 = t[1], v2 = t[2], v3 = t[3];
  std::uint32_t p = 0;
  auto cx = [&p](L& x, L& y) {
    const bool s = y < x;
    const L lo = s ? y : x, hi = s ? x : y;
    x = lo, y = hi, p ^= s;
  };
  cx(v0, v1), cx(v2, v3), cx(v0, v2), cx(v1, v3), cx(v1, v2);
  return {v0, v1, v2, v3, p};
}

}  // namespace

// ---------------------------------------------------------------- frame header

std::string parse_frame_header(std::span<const std::uint8_t> p, FrameHeader& h) {
  if (p.size() < kFrameHeaderSize) return "frame shorter than its 48-byte header";
  h.tet_count = get_u32(p.data());
  h.codec = p[4];
  h.ctx_log2 = p[5];
  h.base_label = get_u64(p.data() + 8);
  h.max_label = get_u64(p.data() + 16);
  std::uint64_t total = kFrameHeaderSize;
  for (int s = 0; s < kFrameStreams; ++s) {
    h.stream_size[s] = get_u32(p.data() + 24 + 4 * s);
    total += h.stream_size[s];
  }
  if (h.tet_count == 0 || h.tet_count > kMaxFrameTets) {
    return "tet count " + std::to_string(h.tet_count) + " out of range 1.." + std::to_string(kMaxFrameTets);
  }
  if (h.codec != kCodecLowerStar) return "unknown codec " + std::to_string(h.codec);
  if (h.ctx_log2 > kMaxCtxLog2) return "context size 2^" + std::to_string(h.ctx_log2) + " too large";
  if (get_u16(p.data() + 6) != 0) return "reserved frame field is not 0";
  if (h.base_label > h.max_label) return "base label above max label";
  if (total != p.size()) return "stream sizes do not add up to the frame length";
  return {};
}

std::vector<std::size_t> frame_boundaries(std::size_t n, std::size_t max_tets) {
  std::vector<std::size_t> b{0};
  if (n == 0) return b;
  max_tets = std::max<std::size_t>(1, max_tets);
  const std::size_t frames = (n + max_tets - 1) / max_tets;
  for (std::size_t f = 1; f <= frames; ++f) b.push_back(n / frames * f + std::min(f, n % frames));
  return b;
}

// ---------------------------------------------------------------- encoder

struct FrameEncoder::Impl {
  explicit Impl(int level) : cctx(ZSTD_createCCtx()) {
    if (!cctx) throw std::bad_alloc();
    ZSTD_CCtx_setParameter(cctx, ZSTD_c_compressionLevel, level);
    ZSTD_CCtx_setParameter(cctx, ZSTD_c_checksumFlag, 1);
    ZSTD_CCtx_setParameter(cctx, ZSTD_c_contentSizeFlag, 1);
  }
  ~Impl() { ZSTD_freeCCtx(cctx); }

  template <class L>
  void encode(std::span<const L> labels, EncodedFrame& out);
  template <class L>
  void sort_by_smallest(std::vector<Canon<L>>& c, std::vector<Canon<L>>& tmp, std::uint64_t base, std::uint64_t max_m);

  ZSTD_CCtx* cctx;
  Context ctx;
  std::vector<std::uint8_t> streams[kFrameStreams];
  std::vector<Canon<std::uint32_t>> c32, tmp32;
  std::vector<Canon<std::uint64_t>> c64, tmp64;
  std::vector<std::uint32_t> counts;
  std::vector<std::uint8_t> codes;                 // per label of a group: its position in K(m), or kNewLabel
  std::vector<std::uint64_t> fresh;                // the new labels of a group, sorted
  std::vector<std::uint32_t> fresh_pos;            // their positions in U(m)
  std::vector<std::uint64_t> ulabels;              // U(m)
  std::vector<std::uint64_t> keys;                 // a group's tets as packed positions in U(m), see kMaxPackedPosition
  std::vector<std::array<std::uint64_t, 4>> wide;  // the same, for groups too big to pack
};

template <class L>
void FrameEncoder::Impl::sort_by_smallest(std::vector<Canon<L>>& c, std::vector<Canon<L>>& tmp, std::uint64_t base,
                                          std::uint64_t max_m) {
  // A counting sort when the labels are dense (the pipeline's batches are), else a
  // comparison sort. The order within a group does not matter: it is sorted later, by
  // positions in U(m).
  const std::size_t n = c.size();
  const std::uint64_t range = max_m - base + 1;
  if (range <= 4 * std::uint64_t(n) + 1024) {
    counts.assign(range + 1, 0);
    for (const auto& x : c) ++counts[x.m - base + 1];
    for (std::uint64_t i = 1; i <= range; ++i) counts[i] += counts[i - 1];
    tmp.resize(n);
    for (const auto& x : c) tmp[counts[x.m - base]++] = x;
    c.swap(tmp);
  } else {
    std::stable_sort(c.begin(), c.end(), [](const auto& x, const auto& y) { return x.m < y.m; });
  }
}

template <class L>
void FrameEncoder::Impl::encode(std::span<const L> labels, EncodedFrame& out) {
  if (labels.size() % 4 != 0) throw std::invalid_argument("tet labels must come 4 per tet");
  const std::size_t n = labels.size() / 4;
  if (n == 0 || n > kMaxFrameTets) {
    throw std::invalid_argument("a frame holds 1.." + std::to_string(kMaxFrameTets) + " tets, not " +
                                std::to_string(n));
  }
  std::vector<Canon<L>>* cp;
  std::vector<Canon<L>>* tp;
  if constexpr (sizeof(L) == 4) {
    cp = &c32, tp = &tmp32;
  } else {
    cp = &c64, tp = &tmp64;
  }
  auto& c = *cp;
  c.resize(n);
  std::uint64_t base = std::numeric_limits<std::uint64_t>::max(), max_m = 0, max_label = 0;
  bool sorted = true;
  for (std::size_t i = 0; i < n; ++i) {
    const Canon<L> x = canonical(labels.data() + 4 * i);
    if (TS_UNLIKELY(!(x.m < x.a && x.a < x.lo && x.lo < x.hi))) {
      throw std::invalid_argument("tet " + std::to_string(i) + " repeats a label");
    }
    c[i] = x;
    sorted &= x.m >= max_m;
    base = std::min<std::uint64_t>(base, x.m);
    max_m = std::max<std::uint64_t>(max_m, x.m);
    max_label = std::max<std::uint64_t>(max_label, x.hi);
  }
  if (!sorted) sort_by_smallest(c, *tp, base, max_m);

  const int log2 = context_log2(base, max_label);
  ctx.reset(log2);
  for (auto& s : streams) s.clear();
  auto& head = streams[kHead];
  auto& absent = streams[kAbsent];
  auto& glo = streams[kGapLo];
  auto& ghi = streams[kGapHi];
  auto& idx = streams[kIndex];
  auto& par = streams[kParity];
  idx.resize(3 * n + 64);  // written through a pointer; trimmed to idx_used below
  std::size_t idx_used = 0;
  par.reserve(n / 8 + 1);

  std::uint64_t prev_m = base;
  std::uint8_t bits = 0;
  unsigned nbits = 0;
  for (std::size_t i = 0; i < n;) {
    const std::uint64_t m = c[i].m;
    std::size_t j = i + 1;
    while (j < n && c[j].m == m) ++j;
    ctx.advance(prev_m, m);
    put_varint(head, m - prev_m);
    prev_m = m;
    alignas(16) std::uint16_t koff[16];
    const unsigned nk = ctx.take(m, koff);

    // Classify each label of the group: known (its position in K(m)) or new.
    const std::size_t t = j - i;
    if (codes.size() < 3 * t) codes.resize(3 * t);
    fresh.clear();
    unsigned seen = 0;
    for (std::size_t k = 0; k < t; ++k) {
      const Canon<L>& x = c[i + k];
      const std::uint64_t v[3] = {x.a, x.lo, x.hi};
      for (int r = 0; r < 3; ++r) {
        const std::uint64_t d = v[r] - m;
        const int q = d <= kMaxOffset ? find_offset(koff, static_cast<std::uint16_t>(d)) : -1;
        if (q >= 0) {
          seen |= 1u << q;
          codes[3 * k + r] = static_cast<std::uint8_t>(q);
        } else {
          codes[3 * k + r] = kNewLabel;
          fresh.push_back(v[r]);
        }
      }
    }
    core::sort_small(fresh.data(), fresh.size());
    fresh.erase(std::unique(fresh.begin(), fresh.end()), fresh.end());
    const unsigned absent_mask = ((1u << nk) - 1) & ~seen;
    put_varint(head, t);
    put_varint(head, unsigned(std::popcount(absent_mask)));
    put_varint(head, fresh.size());
    for (unsigned q = 0, prev = 0, first = 1; q < nk; ++q) {
      if (!(absent_mask >> q & 1)) continue;
      put_varint(absent, first ? q : q - prev - 1);
      prev = q, first = 0;
    }
    std::uint64_t prev_new = m;
    for (const std::uint64_t v : fresh) {
      const std::uint64_t g = v - prev_new - 1;
      prev_new = v;
      glo.push_back(static_cast<std::uint8_t>(g));
      put_varint(ghi, g >> 8);
      ctx.prefetch(m, v);
    }
    // U(m) = the known labels still present merged with the new ones: U(m) itself, the
    // position in it of each known label (by its position in K) and of each new label.
    std::uint32_t known_pos[16];
    if (fresh_pos.size() < fresh.size()) fresh_pos.resize(fresh.size());
    if (ulabels.size() < nk + fresh.size()) ulabels.resize(nk + fresh.size());
    std::uint32_t nu = 0;
    {
      std::size_t f = 0;
      for (unsigned q = 0; q < nk; ++q) {
        if (absent_mask >> q & 1) continue;
        const std::uint64_t v = m + koff[q];
        while (f < fresh.size() && fresh[f] < v) ulabels[nu] = fresh[f], fresh_pos[f++] = nu++;
        ulabels[nu] = v, known_pos[q] = nu++;
        ctx.prefetch(m, v);
      }
      while (f < fresh.size()) ulabels[nu] = fresh[f], fresh_pos[f++] = nu++;
    }
    auto pos = [&](std::size_t k, int r, std::uint64_t v) -> std::uint64_t {
      const std::uint8_t q = codes[3 * k + r];
      if (TS_LIKELY(q != kNewLabel)) return known_pos[q];
      return fresh_pos[std::lower_bound(fresh.begin(), fresh.end(), v) - fresh.begin()];
    };

    // Stored order within the group: by (a, lo, hi, p), i.e. by positions in U(m).
    if (keys.size() < t) keys.resize(t);
    const bool packed = nu <= kMaxPackedPosition;
    if (!packed && wide.size() < t) wide.resize(t);
    for (std::size_t k = 0; k < t; ++k) {
      const Canon<L>& x = c[i + k];
      const std::uint64_t ia = pos(k, 0, x.a), il = pos(k, 1, x.lo), ih = pos(k, 2, x.hi);
      if (packed) {
        keys[k] = ia << 43 | il << 22 | ih << 1 | x.p;
      } else {
        wide[k] = {ia, il, ih, x.p};
      }
    }
    if (packed) {
      core::sort_small(keys.data(), t);
    } else {
      std::sort(wide.begin(), wide.begin() + std::ptrdiff_t(t));
    }

    // At most 3 escaped values of 11 bytes per tet.
    if (idx.size() < idx_used + 33 * t) idx.resize(std::max(2 * idx.size(), idx_used + 33 * t));
    std::uint8_t* ip = idx.data() + idx_used;
    std::uint64_t ia_prev = 0;
    for (std::size_t k = 0; k < t; ++k) {
      std::uint64_t ia, il, ih, p;
      if (packed) {
        const std::uint64_t key = keys[k];
        ia = key >> 43, il = (key >> 22) & kMaxPackedPosition, ih = (key >> 1) & kMaxPackedPosition, p = key & 1;
      } else {
        ia = wide[k][0], il = wide[k][1], ih = wide[k][2], p = wide[k][3];
      }
      ip = put_escaped(ip, ia - ia_prev);
      ip = put_escaped(ip, il - ia - 1);
      ip = put_escaped(ip, ih - il - 1);
      ia_prev = ia;
      bits |= std::uint8_t(p << nbits);
      if (++nbits == 8) par.push_back(bits), bits = 0, nbits = 0;
      ctx.insert_tet(m, ulabels[ia], ulabels[il], ulabels[ih]);
    }
    idx_used = std::size_t(ip - idx.data());
    i = j;
  }
  if (nbits) par.push_back(bits);
  idx.resize(idx_used);

  // Payload: header, then each stream as one zstd frame.
  std::size_t bound = kFrameHeaderSize;
  for (const auto& s : streams) bound += ZSTD_compressBound(s.size());
  out.payload.resize(bound);
  std::uint8_t* p = out.payload.data();
  put_u32(p, static_cast<std::uint32_t>(n));
  p[4] = kCodecLowerStar;
  p[5] = static_cast<std::uint8_t>(log2);
  put_u16(p + 6, 0);
  put_u64(p + 8, base);
  put_u64(p + 16, max_label);
  std::size_t at = kFrameHeaderSize;
  for (int s = 0; s < kFrameStreams; ++s) {
    const std::size_t z = ZSTD_compress2(cctx, p + at, bound - at, streams[s].data(), streams[s].size());
    if (ZSTD_isError(z)) throw std::runtime_error(std::string("zstd: ") + ZSTD_getErrorName(z));
    put_u32(p + 24 + 4 * s, static_cast<std::uint32_t>(z));
    at += z;
  }
  out.payload.resize(at);
  out.tet_count = static_cast<std::uint32_t>(n);
  out.base_label = base;
  out.max_label = max_label;
  out.crc = crc32c(out.payload.data(), out.payload.size());
}

FrameEncoder::FrameEncoder(int zstd_level) : impl_(std::make_unique<Impl>(zstd_level)) {}
FrameEncoder::~FrameEncoder() = default;
void FrameEncoder::encode(std::span<const std::uint32_t> labels, EncodedFrame& out) { impl_->encode(labels, out); }
void FrameEncoder::encode(std::span<const std::uint64_t> labels, EncodedFrame& out) { impl_->encode(labels, out); }

// ---------------------------------------------------------------- decoder

struct FrameDecoder::Impl {
  Impl() : dctx(ZSTD_createDCtx()) {
    if (!dctx) throw std::bad_alloc();
  }
  ~Impl() { ZSTD_freeDCtx(dctx); }

  template <class L>
  void decode(std::span<const std::uint8_t> payload, std::vector<L>& out);
  void unpack(std::span<const std::uint8_t> payload, const FrameHeader& h);

  [[noreturn]] TS_NOINLINE void fail(int stream, const std::string& what) const {
    throw FrameError(std::string("stream ") + kStreamName[stream] + ": " + what, offset[stream]);
  }
  TS_FORCE_INLINE std::uint64_t varint(const std::uint8_t*& p, int stream) const {
    const std::uint64_t b = *p++;
    if (TS_LIKELY(b < 0x80)) return b;
    return varint_slow(p, b, stream);
  }
  TS_NOINLINE std::uint64_t varint_slow(const std::uint8_t*& p, std::uint64_t v, int stream) const {
    v &= 0x7F;
    for (int i = 1; i < 10; ++i) {
      const std::uint64_t b = *p++;
      v |= (b & 0x7F) << (7 * i);
      if (b < 0x80) {
        if (b == 0 || (i == 9 && b > 1)) fail(stream, "malformed varint");
        return v;
      }
    }
    fail(stream, "varint longer than 10 bytes");
  }
  TS_FORCE_INLINE std::uint64_t escaped(const std::uint8_t*& p) const {
    const std::uint64_t b = *p++;
    if (TS_LIKELY(b < 255)) return b;
    const std::uint64_t v = varint(p, kIndex);
    if (v > std::numeric_limits<std::uint64_t>::max() - 255) fail(kIndex, "escaped value overflows");
    return v + 255;
  }

  ZSTD_DCtx* dctx;
  Context ctx;
  std::vector<std::uint8_t> buf[kFrameStreams];
  std::size_t len[kFrameStreams] = {};       // decoded sizes (buf[s] has kStreamPadding more)
  std::uint64_t offset[kFrameStreams] = {};  // of each stream within the payload
  std::vector<std::uint64_t> u;
};

void FrameDecoder::Impl::unpack(std::span<const std::uint8_t> payload, const FrameHeader& h) {
  std::uint64_t at = kFrameHeaderSize;
  // Generous bound on any decoded stream, so a corrupt size cannot ask for terabytes.
  const std::uint64_t limit = 48 * std::uint64_t(h.tet_count) + 64;
  for (int s = 0; s < kFrameStreams; ++s) {
    offset[s] = at;
    const std::uint8_t* src = payload.data() + at;
    const std::size_t size = h.stream_size[s];
    const unsigned long long content = ZSTD_getFrameContentSize(src, size);
    if (content == ZSTD_CONTENTSIZE_ERROR || content == ZSTD_CONTENTSIZE_UNKNOWN) {
      fail(s, "not a zstd frame with a declared content size");
    }
    if (content > limit) fail(s, "declared size " + std::to_string(content) + " too large");
    const std::size_t zsize = ZSTD_findFrameCompressedSize(src, size);
    if (ZSTD_isError(zsize) || zsize != size) fail(s, "zstd frame does not fill the stream");
    buf[s].resize(content + kStreamPadding);
    const std::size_t r = ZSTD_decompressDCtx(dctx, buf[s].data(), content, src, size);
    if (ZSTD_isError(r)) fail(s, std::string("zstd: ") + ZSTD_getErrorName(r));
    if (r != content) fail(s, "zstd frame shorter than declared");
    std::memset(buf[s].data() + content, 0, kStreamPadding);
    len[s] = content;
    at += size;
  }
}

template <class L>
void FrameDecoder::Impl::decode(std::span<const std::uint8_t> payload, std::vector<L>& out) {
  FrameHeader h;
  if (const std::string problem = parse_frame_header(payload, h); !problem.empty()) throw FrameError(problem, 0);
  if (sizeof(L) == 4 && h.max_label > std::numeric_limits<std::uint32_t>::max()) {
    throw FrameError("labels do not fit 32 bits", 16);
  }
  unpack(payload, h);
  ctx.reset(h.ctx_log2);

  const std::uint8_t* hp = buf[kHead].data();
  const std::uint8_t* ap = buf[kAbsent].data();
  const std::uint8_t* lp = buf[kGapLo].data();
  const std::uint8_t* gp = buf[kGapHi].data();
  const std::uint8_t* ip = buf[kIndex].data();
  const std::uint8_t* pp = buf[kParity].data();
  const std::uint8_t* const h_end = hp + len[kHead];
  const std::uint8_t* const a_end = ap + len[kAbsent];
  const std::uint8_t* const l_end = lp + len[kGapLo];
  const std::uint8_t* const g_end = gp + len[kGapHi];
  const std::uint8_t* const i_end = ip + len[kIndex];
  const std::uint64_t T = h.tet_count;
  if (len[kParity] != (T + 7) / 8) fail(kParity, "size is not one bit per tet");

  out.resize(4 * T);
  L* o = out.data();
  std::uint64_t prev_m = h.base_label, done = 0, bit = 0;
  std::uint64_t known[kSlotCapacity];
  while (done < T) {
    const std::uint64_t dm = varint(hp, kHead);
    const std::uint64_t m = prev_m + dm;
    if (done == 0 ? dm != 0 : (dm == 0 || m < prev_m || m > h.max_label)) fail(kHead, "bad label step");
    ctx.advance(prev_m, m);
    prev_m = m;
    const std::uint64_t t = varint(hp, kHead);
    const std::uint64_t n_abs = varint(hp, kHead);
    const std::uint64_t n_new = varint(hp, kHead);
    if (hp > h_end) fail(kHead, "ends early");
    if (t == 0 || t > T - done) fail(kHead, "bad tet count in the group of label " + std::to_string(m));
    if (n_new > 3 * t) fail(kHead, "too many new labels in the group of label " + std::to_string(m));

    alignas(16) std::uint16_t koff[16];
    unsigned nk = ctx.take(m, koff);
    for (unsigned q = 0; q < nk; ++q) known[q] = m + koff[q];
    if (n_abs > nk) fail(kHead, "more absent labels than known ones");
    if (n_abs) {  // drop the absent ones
      std::uint64_t next = varint(ap, kAbsent), left = n_abs - 1;
      unsigned w = 0;
      for (unsigned q = 0; q < nk; ++q) {
        if (q == next) {
          next = left ? q + 1 + varint(ap, kAbsent) : ~std::uint64_t(0);
          left -= left != 0;
          continue;
        }
        known[w++] = known[q];
      }
      if (w != nk - n_abs) fail(kAbsent, "absent position out of range");
      nk = w;
      if (ap > a_end) fail(kAbsent, "ends early");
    }
    // U(m): merge the known labels with the new ones.
    if (u.size() < nk + n_new) u.resize(nk + n_new + 64);
    std::uint64_t* U = u.data();
    std::size_t nu = 0, kq = 0;
    std::uint64_t prev = m;
    for (std::uint64_t q = 0; q < n_new; ++q) {
      const std::uint64_t hi = varint(gp, kGapHi);
      if (hi > (std::numeric_limits<std::uint64_t>::max() >> 8)) fail(kGapHi, "gap overflows");
      const std::uint64_t g = hi << 8 | *lp++;
      const std::uint64_t v = prev + g + 1;
      if (v <= prev || v > h.max_label)
        fail(kGapHi, "new label out of range in the group of label " + std::to_string(m));
      prev = v;
      while (kq < nk && known[kq] < v) U[nu++] = known[kq++];
      if (kq < nk && known[kq] == v) fail(kGapHi, "new label already known");
      U[nu++] = v;
    }
    while (kq < nk) U[nu++] = known[kq++];
    if (lp > l_end || gp > g_end) fail(lp > l_end ? kGapLo : kGapHi, "ends early");
    for (std::size_t q = 0; q < nu; ++q) ctx.prefetch(m, U[q]);

    std::uint64_t ia = 0;
    for (std::uint64_t k = 0; k < t; ++k) {
      const std::uint64_t d0 = escaped(ip), d1 = escaped(ip), d2 = escaped(ip);
      if (TS_UNLIKELY(d0 >= nu || d1 >= nu || d2 >= nu || ip > i_end)) fail(kIndex, "position out of range");
      ia += d0;
      const std::uint64_t il = ia + 1 + d1, ih = il + 1 + d2;
      if (TS_UNLIKELY(ih >= nu)) fail(kIndex, "position out of range in the group of label " + std::to_string(m));
      const std::uint64_t a = U[ia], lo = U[il], hi = U[ih];
      const bool odd = (pp[bit >> 3] >> (bit & 7)) & 1;
      ++bit;
      o[0] = static_cast<L>(m);
      o[1] = static_cast<L>(a);
      o[2] = static_cast<L>(odd ? hi : lo);
      o[3] = static_cast<L>(odd ? lo : hi);
      o += 4;
      ctx.insert_tet(m, a, lo, hi);
    }
    done += t;
  }
  if (hp != h_end) fail(kHead, "has bytes left over");
  if (ap != a_end) fail(kAbsent, "has bytes left over");
  if (lp != l_end) fail(kGapLo, "has bytes left over");
  if (gp != g_end) fail(kGapHi, "has bytes left over");
  if (ip != i_end) fail(kIndex, "has bytes left over");
  if ((T & 7) && (pp[T >> 3] >> (T & 7))) fail(kParity, "padding bits are not 0");
}

FrameDecoder::FrameDecoder() : impl_(std::make_unique<Impl>()) {}
FrameDecoder::~FrameDecoder() = default;
void FrameDecoder::decode(std::span<const std::uint8_t> payload, std::vector<std::uint64_t>& labels) {
  impl_->decode(payload, labels);
}
void FrameDecoder::decode(std::span<const std::uint8_t> payload, std::vector<std::uint32_t>& labels) {
  impl_->decode(payload, labels);
}

}  // namespace tetstream::io
