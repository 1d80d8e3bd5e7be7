#pragma once
// A step's records built by lower stars (verify's preparing threads, build_step in
// frames.ipp): the sorted facet records and the sorted, distinct edges of a run of
// canonical tets in order of their smallest labels, as a container's frames store them
// (format.md §4.1) and `tetstream run` writes them.
//
// Why: sorting every record of a step was most of verify's work (about 28 of 44 CPU
// seconds on a clustered 10^7 output, steps of 2^18 tets: the facets' radix sort, the
// sorts of the lower stars, the edges'). Here every record is keyed by a label of the
// step's span, so the records fall into one small group a key: the A records (through a
// tet's smallest label u) of u's lower star are adjacent already; the B records (the
// facet and edges away from it) are placed in their key's bucket by one counting pass.
// Each group is then sorted on its own (a few dozen records), and a key's edges are
// kept once through a small table of the labels it met. The result is the sequence a
// full sort gives: FacetLess is a total order on the records of distinct tets, and the
// edges are sorted and distinct.
#include "pipeline/verify/records.hpp"

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace tetstream::pipeline::verify_engine {

// The most labels a step's keys may span here: their counts take 8 bytes a label of it
// (8 MiB at steps of 2^18 tets). A step whose keys reach further (long tets on the hull
// of a large output) is sorted whole.
inline std::size_t lower_star_span_cap(std::size_t step_tets) {
  return std::max<std::size_t>(4 * step_tets, std::size_t(1) << 16);
}

// Buffers reused from step to step (one set for each frame being prepared).
template <class L>
struct LowerStarScratch {
  std::vector<std::uint32_t> facet_end, edge_end;  // by key: where its B bucket ends
  std::vector<FacetRec<L>> b, far;                 // B facets by key; those past the span
  std::vector<L> b_edges;                          // B edges' larger labels by key
  std::vector<EdgeKey<L>> far_edges;               // B edges keyed past the span
  std::vector<EdgeKey<L>> b_kept, seen;            // B edges in the span, not repeats; the
                                                   // last ones made (2^kSeenBits)
  std::vector<EdgeKey<L>> edge_out;                // the step's edges, before their copy
  std::vector<L> met;                              // one key's edges' larger labels, repeated
  struct Seen {
    L label;
    std::uint32_t key;  // the key (its count from 1) that met the label; 0: none
  };
  std::vector<Seen> seen_labels;     // open addressing, kLabelSlots
  std::uint32_t keys = 0;            // keys that used it so far
  std::vector<FacetRec<L>> group;    // one key's facet records
  std::vector<std::uint64_t> order;  // and their sort keys
};

// Sorts [first, first + n) with less: insertion sort for the small groups that most keys
// have, std::sort beyond.
template <class T, class Less>
void sort_small(T* first, std::size_t n, const Less& less) {
  if (n > 32) {
    std::sort(first, first + n, less);
    return;
  }
  for (std::size_t i = 1; i < n; ++i) {
    const T x = first[i];
    std::size_t j = i;
    for (; j > 0 && less(x, first[j - 1]); --j) first[j] = first[j - 1];
    first[j] = x;
  }
}

// Moves the distinct labels of w.met to its front, in some order; returns how many.
// Most keys meet a few dozen labels: a table of 2 slots a label, in the first level
// cache, stamped with the key's count so that it is never cleared; more are sorted.
constexpr int kLabelBits = 7;
constexpr std::size_t kLabelSlots = std::size_t(1) << kLabelBits;
template <class L>
std::size_t distinct_labels(LowerStarScratch<L>& w) {
  std::vector<L>& met = w.met;
  if (met.size() > kLabelSlots / 2) {
    std::sort(met.begin(), met.end());
    return std::size_t(std::unique(met.begin(), met.end()) - met.begin());
  }
  if (w.seen_labels.empty() || ++w.keys == 0) w.seen_labels.assign(kLabelSlots, {L(0), 0}), w.keys = 1;
  std::size_t kept = 0;
  for (const L v : met) {
    std::size_t at = std::size_t((std::uint64_t(v) * 0x9E3779B97F4A7C15ull) >> (64 - kLabelBits));
    for (;; at = (at + 1) % kLabelSlots) {
      auto& slot = w.seen_labels[at];
      if (slot.key != w.keys) {
        slot = {v, w.keys};
        met[kept++] = v;
        break;
      }
      if (slot.label == v) break;
    }
  }
  return kept;
}

// The records of tets [0, n) of a step: canon their canonical labels (sorted), flags
// bit 0 the parity, bit 1 broken (no records); tet i has ordinal first_ordinal + i.
// The good tets must come in nondecreasing order of smallest label, every one in
// [base, base + span); span <= 2^32 and 3 n < 2^32 (the buckets' counts).
// keep_facet(f): whether facet record f is made; keep_key(u): whether edges keyed u are
// made; edges: whether any are (the sample makes none). facets: sorted by FacetLess;
// edge_keys: sorted, distinct.
template <class L, class KeepFacet, class KeepKey>
void lower_star_records(const L* canon, const std::uint8_t* flags, std::size_t n, std::uint64_t first_ordinal,
                        std::uint64_t base, std::size_t span, const KeepFacet& keep_facet, const KeepKey& keep_key,
                        bool edges, LowerStarScratch<L>& w, std::vector<FacetRec<L>>& facets,
                        std::vector<EdgeKey<L>>& edge_keys) {
  using Facet = FacetRec<L>;
  const FacetLess<L> less;
  auto good = [&](std::size_t i) { return !(flags[i] & 2); };
  auto in_span = [&](L label, std::size_t& k) {
    k = std::size_t(std::uint64_t(label) - base);
    return std::uint64_t(label) - base < span;
  };
  // B records into their key's bucket: counted (end[k + 1]), the counts summed into
  // starts, then placed, which leaves end[k] at bucket k's end.
  auto buckets = [&](std::vector<std::uint32_t>& end, auto&& each) {
    end.assign(span + 1, 0);
    each([&](std::size_t k) { ++end[k + 1]; });
    for (std::size_t k = 0; k < span; ++k) end[k + 1] += end[k];
  };
  buckets(w.facet_end, [&](auto&& count) {
    w.far.clear();
    for (std::size_t i = 0; i < n; ++i) {
      if (!good(i)) continue;
      const Facet f = facet_opposite<0>(canon + 4 * i, first_ordinal + i, flags[i] & 1);
      std::size_t k;
      if (!keep_facet(f)) continue;
      if (in_span(f.v[0], k))
        count(k);
      else
        w.far.push_back(f);
    }
  });
  w.b.resize(w.facet_end[span]);
  for (std::size_t i = 0; i < n; ++i) {
    if (!good(i)) continue;
    const Facet f = facet_opposite<0>(canon + 4 * i, first_ordinal + i, flags[i] & 1);
    std::size_t k;
    if (keep_facet(f) && in_span(f.v[0], k)) w.b[w.facet_end[k]++] = f;
  }
  // The B edges (s1, s2), (s1, s3), (s2, s3): their larger labels by key.
  auto b_edges = [&](auto&& each) {
    for (std::size_t i = 0; i < n; ++i) {
      if (!good(i)) continue;
      const L* s = canon + 4 * i;
      each(s[1], s[2]), each(s[1], s[3]), each(s[2], s[3]);
    }
  };
  if (edges) {
    // A table of the last edges made drops most repeats before they are placed (an
    // edge is in several tets of a step); cleared every step, so that the step's edges
    // do not depend on the steps before.
    w.seen.assign(std::size_t(1) << kSeenBits, make_edge(L(0), L(0)));  // no edge has u == v
    buckets(w.edge_end, [&](auto&& count) {
      w.far_edges.clear(), w.b_kept.clear();
      b_edges([&](L u, L v) {
        std::size_t k;
        if (!keep_key(u)) return;
        const EdgeKey<L> e = make_edge(u, v);
        EdgeKey<L>& last = w.seen[edge_slot(u, v, kSeenBits)];
        if (last == e) return;
        last = e;
        if (in_span(u, k))
          count(k), w.b_kept.push_back(e);
        else
          w.far_edges.push_back(e);
      });
    });
    w.b_edges.resize(w.edge_end[span]);
    for (const EdgeKey<L>& e : w.b_kept) w.b_edges[w.edge_end[std::size_t(edge_u(e) - base)]++] = L(edge_v(e));
  }

  auto group_less = [](const Facet& a, const Facet& b) {  // one key's records: v[0] is the same
    if (a.v[1] != b.v[1]) return a.v[1] < b.v[1];
    if (a.v[2] != b.v[2]) return a.v[2] < b.v[2];
    const std::uint64_t pa = a.x & kPayload, pb = b.x & kPayload;
    if (pa != pb) return pa < pb;
    return a.x < b.x;
  };
  // A key's records are sorted as integers: (v1, v2) relative to base in span_bits each
  // and the record's place in the group below them. The group is laid out in ordinal
  // order where keys tie (first the B records, which come from tets before u's lower
  // star, in the order of their tets; then the lower star's, tet by tet), so the place
  // breaks ties as FacetLess does. The facets opposite s3 and s2 of the lower star come
  // sorted or nearly (the tets are in order of their labels, format.md §4.1) and are
  // sorted apart from the others (opposite s1, and B), then the two are merged. Groups
  // with a label past the span, or too many records for the bits left, are sorted as
  // records.
  const int span_bits = std::max(1, int(std::bit_width(std::uint64_t(span - 1))));
  const int place_bits = 64 - 2 * span_bits;
  const std::uint64_t place_mask = place_bits > 0 ? (std::uint64_t(1) << place_bits) - 1 : 0;
  // Outputs sized to their bounds, written through pointers, trimmed at the end.
  facets.resize(3 * n + w.b.size() + w.far.size());
  if (w.edge_out.size() < 3 * n + w.b_edges.size() + w.far_edges.size())
    w.edge_out.resize(3 * n + w.b_edges.size() + w.far_edges.size());
  Facet* out = facets.data();
  EdgeKey<L>* out_edge = w.edge_out.data();
  std::size_t i = 0;
  for (std::size_t k = 0; k < span; ++k) {
    const L u = L(base + k);
    const std::size_t from = k ? w.facet_end[k - 1] : 0, to = w.facet_end[k];
    std::size_t end = i;  // u's lower star: the good tets in [i, end) whose smallest label is u
    while (end < n && (!good(end) || canon[4 * end] == u)) ++end;
    if (from == to && end == i && !(edges && (k ? w.edge_end[k - 1] : 0) < w.edge_end[k])) continue;
    const std::size_t most = (to - from) + 3 * (end - i);
    if (w.group.size() < most) w.group.resize(most), w.order.resize(2 * most);
    Facet* group = w.group.data();
    std::uint64_t *sorted = w.order.data(), *rest = sorted + most;  // the two parts' keys
    std::size_t m = 0, ns = 0, nr = 0;
    bool as_integers = place_bits >= 8 && most <= place_mask;
    auto put = [&](const Facet& f, std::uint64_t* part, std::size_t& count) {
      const std::uint64_t a = std::uint64_t(f.v[1]) - base, b = std::uint64_t(f.v[2]) - base;
      as_integers = as_integers && b < span;  // and a < b
      part[count++] = (a << span_bits | b) << place_bits | m;
      group[m++] = f;
    };
    for (std::size_t j = from; j < to; ++j) put(w.b[j], rest, nr);
    const bool keep_edges = edges && keep_key(u);
    w.met.clear();
    for (; i < end; ++i) {
      if (!good(i)) continue;
      const L* s = canon + 4 * i;
      const std::uint64_t ordinal = first_ordinal + i;
      const int parity = flags[i] & 1;
      if (const Facet f = facet_opposite<3>(s, ordinal, parity); keep_facet(f)) put(f, sorted, ns);
      if (const Facet f = facet_opposite<2>(s, ordinal, parity); keep_facet(f)) put(f, sorted, ns);
      if (const Facet f = facet_opposite<1>(s, ordinal, parity); keep_facet(f)) put(f, rest, nr);
      if (keep_edges) w.met.push_back(s[1]), w.met.push_back(s[2]), w.met.push_back(s[3]);
    }
    if (as_integers) {
      sort_small(sorted, ns, std::less<std::uint64_t>());
      sort_small(rest, nr, std::less<std::uint64_t>());
      const std::uint64_t *p = sorted, *pe = sorted + ns, *q = rest, *qe = rest + nr;
      while (p != pe && q != qe) {  // without a branch on the keys
        const bool from_rest = *q < *p;
        *out++ = group[(from_rest ? *q : *p) & place_mask];
        q += from_rest, p += !from_rest;
      }
      for (; p != pe; ++p) *out++ = group[*p & place_mask];
      for (; q != qe; ++q) *out++ = group[*q & place_mask];
    } else {
      sort_small(group, m, group_less);
      out = std::copy(group, group + m, out);
    }
    if (!keep_edges) continue;
    w.met.insert(w.met.end(), w.b_edges.begin() + std::ptrdiff_t(k ? w.edge_end[k - 1] : 0),
                 w.b_edges.begin() + std::ptrdiff_t(w.edge_end[k]));
    const std::size_t distinct = distinct_labels(w);
    sort_small(w.met.data(), distinct, std::less<L>());
    for (std::size_t j = 0; j < distinct; ++j) *out_edge++ = make_edge(u, w.met[j]);
  }
  // Keys past the span follow every key in it.
  std::sort(w.far.begin(), w.far.end(), less);
  out = std::copy(w.far.begin(), w.far.end(), out);
  facets.resize(std::size_t(out - facets.data()));
  edge_keys.clear();
  if (edges) {
    std::sort(w.far_edges.begin(), w.far_edges.end());
    out_edge = std::copy(w.far_edges.begin(), std::unique(w.far_edges.begin(), w.far_edges.end()), out_edge);
    edge_keys.assign(w.edge_out.data(), out_edge);
  }
}

}  // namespace tetstream::pipeline::verify_engine
