#pragma once
// The records a periodic job and `verify` sort (pipeline/files/external_sort.hpp): a
// periodic tet in the container's stored form, and one facet of it, both with their
// vertices' offsets in periods (docs/periodic.md, "Offsets").
//
// Anatomy. A periodic tet is four labels and an offset o_i in {-1, 0, 1}^3 a vertex:
// vertex i stands at x(label_i) + o_i L. Stored form (format.md §4.1): the even
// rotation (m, a, b, c) with m the smallest label, a the smallest of the others, and
// offsets relative to m (o_m = 0). A facet is keyed by its three labels sorted
// (v0 < v1 < v2) and the offsets of v1, v2 relative to v0; `side` is the parity of
// the sort, so the two tets that share a facet give it opposite sides.
#include "io/tet_periodic.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/files/external_sort.hpp"

#include <vector>

#include <algorithm>
#include <bit>
#include <cstdint>
#include <iterator>
#include <string>
#include <tuple>
#include <utility>

namespace tetstream::pipeline::periodic {

// The external sort of one kind of record, in the job's directory (DIR/NAME-K.run).
inline ExternalSortOptions sort_options(std::size_t memory_bytes, const std::string& dir, const char* name) {
  ExternalSortOptions o;
  o.memory_bytes = memory_bytes;
  o.dir = dir;
  o.name = name;
  return o;
}

struct KeptTet {
  std::uint64_t v[4];  // m, a, b, c
  std::uint16_t code;  // io::tet_offset_code of a, b, c relative to m
  std::uint8_t pad[6];
};
static_assert(sizeof(KeptTet) == 40);
// The stored order (format.md §4.1): (m, a, lo, hi), then the parity and the offsets,
// which only break ties between copies that a valid output never has.
struct KeptTetLess {
  bool operator()(const KeptTet& x, const KeptTet& y) const {
    if (x.v[0] != y.v[0]) return x.v[0] < y.v[0];
    if (x.v[1] != y.v[1]) return x.v[1] < y.v[1];
    const std::uint64_t xl = std::min(x.v[2], x.v[3]), yl = std::min(y.v[2], y.v[3]);
    if (xl != yl) return xl < yl;
    const std::uint64_t xh = std::max(x.v[2], x.v[3]), yh = std::max(y.v[2], y.v[3]);
    if (xh != yh) return xh < yh;
    if ((x.v[2] > x.v[3]) != (y.v[2] > y.v[3])) return x.v[2] < x.v[3];
    return x.code < y.code;
  }
};

// The same order: a radix sort on the smallest label alone (`label_bits` bits), then each group (the tets of one
// smallest label, about seven) by insertion. Two to three passes over the records instead of eight to ten for a radix
// sort on all four labels: the sort was a tenth of a periodic job's time.
inline void radix_sort_kept(KeptTet* data, std::size_t n, int label_bits) {
  if (n < 2) return;
  // On the labels' span alone: the keep step's batches span a few slabs of labels.
  std::uint64_t lo = data[0].v[0], hi = lo;
  for (std::size_t i = 1; i < n; ++i) lo = std::min(lo, data[i].v[0]), hi = std::max(hi, data[i].v[0]);
  const int bits = std::min(label_bits, int(std::bit_width(hi - lo)));
  std::vector<KeptTet> tmp;
  radix_sort(data, n, tmp, std::max(bits, 1), [lo](const KeptTet& t) { return t.v[0] - lo; });
  const KeptTetLess less;
  for (std::size_t g = 0; g < n;) {
    std::size_t e = g + 1;
    while (e < n && data[e].v[0] == data[g].v[0]) ++e;
    if (e - g > 32) {  // a vertex with a large lower star (a lattice's corner)
      std::sort(data + g, data + e, less);
    } else {
      for (std::size_t j = g + 1; j < e; ++j) {
        const KeptTet x = data[j];
        std::size_t i = j;
        for (; i > g && less(x, data[i - 1]); --i) data[i] = data[i - 1];
        data[i] = x;
      }
    }
    g = e;
  }
}

// The twelve even permutations of (0, 1, 2, 3).
inline constexpr int kEven[12][4] = {{0, 1, 2, 3}, {0, 2, 3, 1}, {0, 3, 1, 2}, {1, 0, 3, 2},
                                     {1, 2, 0, 3}, {1, 3, 2, 0}, {2, 0, 1, 3}, {2, 1, 3, 0},
                                     {2, 3, 0, 1}, {3, 0, 2, 1}, {3, 1, 0, 2}, {3, 2, 1, 0}};

// A tet as four labels and offsets (any reference vertex), positively oriented, to its
// stored form. False when an offset relative to m leaves {-1, 0, 1} (a tet wider
// than a period) or two labels are equal.
inline bool stored_form(const std::uint64_t label[4], const int off[4][3], KeptTet& out) {
  int mi = 0;
  for (int i = 1; i < 4; ++i) mi = label[i] < label[mi] ? i : mi;
  int ai = -1;
  for (int i = 0; i < 4; ++i) {
    if (i == mi) continue;
    if (label[i] == label[mi]) return false;
    if (ai < 0 || label[i] < label[ai]) ai = i;
  }
  const int* p = nullptr;
  for (const auto& e : kEven) p = (e[0] == mi && e[1] == ai) ? e : p;
  int codes[3];
  for (int j = 1; j < 4; ++j) {
    int o[3];
    for (int k = 0; k < 3; ++k) {
      o[k] = off[p[j]][k] - off[mi][k];
      if (o[k] < -1 || o[k] > 1) return false;
    }
    codes[j - 1] = io::offset_code(o);
  }
  if (label[p[2]] == label[p[3]] || label[p[1]] == label[p[2]] || label[p[1]] == label[p[3]]) return false;
  for (int j = 0; j < 4; ++j) out.v[j] = label[p[j]];
  out.code = io::tet_offset_code(codes[0], codes[1], codes[2]);
  std::fill(std::begin(out.pad), std::end(out.pad), 0);
  return true;
}

// The offsets of a stored tet's four vertices (m's is 0).
inline void stored_offsets(const KeptTet& t, int off[4][3]) {
  int c[3];
  io::tet_offset_codes(t.code, c);
  off[0][0] = off[0][1] = off[0][2] = 0;
  for (int j = 0; j < 3; ++j) io::offset_of_code(c[j], off[j + 1]);
}

// Calls visit(tet, frame, index) for every tet of a periodic container in stored
// order, in stored form with its offsets (frames decoded one at a time, their pages
// handed back after).
template <class Visit>
void for_each_stored_tet(const io::TetReader& r, const io::PeriodicOffsetsReader& offsets, Visit&& visit) {
  std::vector<std::uint64_t> labels;
  std::vector<std::uint16_t> codes;
  for (std::uint64_t f = 0; f < r.frame_count(); ++f) {
    r.read_frame(f, labels);
    offsets.read(f, codes);
    for (std::size_t i = 0; i < codes.size(); ++i) {
      KeptTet t;
      std::copy(&labels[4 * i], &labels[4 * i] + 4, t.v);
      t.code = codes[i];
      std::fill(std::begin(t.pad), std::end(t.pad), 0);
      visit(t, f, i);
    }
    r.release_frame_pages(f);
  }
}

struct FacetRec {
  std::uint64_t v[3];     // sorted labels
  std::uint64_t opp;      // the opposite vertex's label
  std::uint16_t off;      // 27 c1 + c2: v1's and v2's offsets relative to v0
  std::uint8_t opp_code;  // the opposite vertex's offset relative to v0
  std::uint8_t side;      // parity of the sort of the outward-oriented facet
  std::uint32_t pad;
};
static_assert(sizeof(FacetRec) == 40);
inline auto facet_key(const FacetRec& f) { return std::make_tuple(f.v[0], f.v[1], f.v[2], f.off); }
struct FacetLess {
  bool operator()(const FacetRec& x, const FacetRec& y) const {
    return std::make_tuple(x.v[0], x.v[1], x.v[2], x.off, x.side, x.opp, x.opp_code) <
           std::make_tuple(y.v[0], y.v[1], y.v[2], y.off, y.side, y.opp, y.opp_code);
  }
};

// Facet i of a positively oriented tet (t0..t3), ordered so that t_i lies on its
// positive side: orient3d(F_i, t_i) > 0.
inline constexpr int kFacet[4][3] = {{1, 3, 2}, {0, 2, 3}, {0, 3, 1}, {0, 1, 2}};

// The four facets of a stored tet. False when an offset relative to a facet's
// smallest label leaves {-1, 0, 1}.
inline bool facets_of(const KeptTet& t, FacetRec out[4]) {
  int off[4][3];
  stored_offsets(t, off);
  for (int i = 0; i < 4; ++i) {
    int idx[3] = {kFacet[i][0], kFacet[i][1], kFacet[i][2]};
    int parity = 0;  // bubble sort of three by label, counting swaps
    for (int pass = 0; pass < 2; ++pass) {
      for (int j = 0; j + 1 < 3 - pass; ++j) {
        if (t.v[idx[j]] > t.v[idx[j + 1]]) {
          std::swap(idx[j], idx[j + 1]);
          parity ^= 1;
        }
      }
    }
    FacetRec& f = out[i];
    int rel[4][3];
    const int base = idx[0];
    const int members[4] = {idx[1], idx[2], i, 0};
    for (int j = 0; j < 3; ++j) {
      for (int k = 0; k < 3; ++k) {
        rel[j][k] = off[members[j]][k] - off[base][k];
        if (rel[j][k] < -1 || rel[j][k] > 1) return false;
      }
    }
    for (int j = 0; j < 3; ++j) f.v[j] = t.v[idx[j]];
    f.opp = t.v[i];
    f.off = std::uint16_t(27 * io::offset_code(rel[0]) + io::offset_code(rel[1]));
    f.opp_code = std::uint8_t(io::offset_code(rel[2]));
    f.side = std::uint8_t(parity);
    f.pad = 0;
  }
  return true;
}

}  // namespace tetstream::pipeline::periodic
