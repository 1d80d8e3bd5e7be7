// A frame's tets: storage, orientation, volume, and their facets and edges (members of Engine,
// pipeline/verify/engine.hpp; compiled in engine.cpp). Included once, by engine.cpp, inside namespace
// tetstream::pipeline::verify_engine.

template <class L>
template <class OnGood>
void Engine<L>::canonicalize(std::size_t k, std::vector<L>& labels, std::vector<std::uint8_t>& flags, bool log_storage,
                             bool parallel, OnGood&& on_good) {
  const VerifySource::Batch b = src_.batch(k);
  const std::size_t t = labels.size() / 4;
  if (labels.size() % 4 != 0 || t != b.tet_count)
    throw InputError(src_.name() + ": frame " + std::to_string(k) + ": " + std::to_string(labels.size() / 4) +
                     " tets decoded, " + std::to_string(b.tet_count) + " expected");
  // Canonical form in place: the labels sorted; flags bit 0: odd permutation (the
  // sorted order has the opposite orientation), bit 1: broken (storage).
  flags.assign(t, 0);
  constexpr std::size_t kChunk = 4096;
  const std::int64_t chunks = std::int64_t((t + kChunk - 1) / kChunk);
  bool below_min = false, above_max = false;
#pragma omp parallel for schedule(dynamic, 4) reduction(|| : below_min, above_max) if (parallel)
  for (std::int64_t c = 0; c < chunks; ++c) {
    const std::size_t lo = std::size_t(c) * kChunk, hi = std::min(t, lo + kChunk);
    for (std::size_t i = lo; i < hi; ++i) {
      L* v = labels.data() + 4 * i;
      if (i + 8 < hi)  // the coordinates of a tet ahead: on_good reads them
        for (int j = 0; j < 4; ++j) xyz_.prefetch(std::min<std::uint64_t>(v[32 + j], n_ ? n_ - 1 : 0));
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
      flags[i] = std::uint8_t(swaps & 1);
      if (!ok) {
        flags[i] |= 2;
        if (log_storage)
          log_.add(Violation::kStorage, ordinal, [&] {
            return tet_text(ordinal, g[0], g[1], g[2], g[3]) + ": labels must be distinct and below " +
                   std::to_string(n_);
          });
        continue;
      }
      if (std::uint64_t(v[0]) < b.min_label) below_min = true;
      if (std::uint64_t(v[3]) > b.max_label) above_max = true;
      on_good(i, ordinal, g);
    }
  }
  // The frame's declared label range is a promise the pass relies on (keys below the
  // smallest label to come are final; a distributed job's front is cut by it).
  if (below_min)
    throw InputError(src_.name() + ": frame " + std::to_string(k) +
                     ": a label below the frame's declared smallest label " + std::to_string(b.min_label));
  if (above_max)
    throw InputError(src_.name() + ": frame " + std::to_string(k) +
                     ": a label above the frame's declared largest label " + std::to_string(b.max_label));
}

// One frame, off the ordered path (several at once): decoded into a scratch of the
// pass, storage, orientation and volume of every tet (volumes into the
// slot's sums), then each step's sorted facet and edge records into the slot. future_min: the smallest label of the
// frames after this one. A failure is kept in the slot for consume_frame(), which meets the frames in order.
template <class L>
void Engine<L>::prepare_frame(std::size_t k, std::uint64_t future_min, Slot& slot, Scratch& w) {
  slot.step_count = 0, slot.tets = 0, slot.good = 0, slot.checked = 0;
  slot.volume6 = ExactSum(), slot.error6 = ExactSum();
  slot.error = nullptr;
  try {
    src_.read_batch(k, w.labels);
    std::vector<L>& labels = w.labels;
    const VerifySource::Batch b = src_.batch(k);
    std::uint64_t good = 0, checked = 0;
    canonicalize(k, labels, w.flags, true, false, [&](std::size_t, std::uint64_t ordinal, const L* g) {
      ++good;
      for (int j = 0; j < 4; ++j) used_.set(g[j]);
      const PointCoords::Point p0 = P(g[0]), p1 = P(g[1]), p2 = P(g[2]), p3 = P(g[3]);
      if (wide_volume_) {
        const BoundedDet<long double> v = volume6(p0, p1, p2, p3);
        slot.volume6.add(std::fabs(v.value));
        slot.error6.add(v.error);
      } else {  // the same terms, without a round trip through long double
        const BoundedDet<double> v = det3_bounded<double>(p0, p1, p2, p3);
        slot.volume6.add(std::fabs(v.value));
        slot.error6.add(v.error);
      }
      if (tet_sampled(ordinal)) {
        ++checked;
        const int o = core::orient3d(p0, p1, p2, p3);
        if (o <= 0)
          log_.add(Violation::kOrientation, ordinal, [&] {
            return tet_text(ordinal, g[0], g[1], g[2], g[3]) +
                   (o == 0 ? ": flat (orient3d = 0)" : ": negatively oriented (orient3d = -1)");
          });
      }
    });
    slot.good = good, slot.checked = checked;
    const std::vector<std::uint8_t>& flags = w.flags;

    // Steps: after each, keys below the smallest label still to come (in later steps
    // of this frame or in later frames) are final.
    const std::size_t t = labels.size() / 4, step = step_tets_;
    const std::size_t steps = (t + step - 1) / step;
    if (slot.steps.size() < steps) slot.steps.resize(steps);
    std::uint64_t m = future_min;
    for (std::size_t s = steps; s-- > 0;) {
      slot.steps[s].threshold = m;
      for (std::size_t i = s * step, hi = std::min(t, (s + 1) * step); i < hi; ++i)
        if (!(flags[i] & 2)) m = std::min<std::uint64_t>(m, labels[4 * i]);
    }
    for (std::size_t s = 0; s < steps; ++s) {
      const std::size_t lo = s * step, hi = std::min(t, lo + step);
      bool sorted = true;
      for (std::size_t i = lo + 1; i < hi && sorted; ++i) sorted = labels[4 * i] >= labels[4 * (i - 1)];
      build_step(w, slot.steps[s], labels.data() + 4 * lo, flags.data() + lo, lo, hi, b.first_tet, sorted);
    }
    slot.step_count = steps, slot.tets = t;
  } catch (...) {
    slot.error = std::current_exception();
  }
}

// One prepared frame, in order: each step's records merged with the open sets (open
// first on equal keys) and each key's run folded in that order, the pairs formed kept
// in the slot for their insphere tests (check_pairs(), on any thread: they are
// independent). In one pass: a key no later tet can touch (below the step's threshold)
// is final at once (or goes to the spill), and only the keys still open are copied,
// into the other buffer; the step's records are not written again.
template <class L>
void Engine<L>::consume_frame(Slot& slot) {
  if (slot.error) std::rethrow_exception(slot.error);
  tets_checked_ += slot.checked, orient_tests_ += slot.checked;
  good_tets_ += slot.good;
  tet_volume6_.add(slot.volume6);
  tet_error6_.add(slot.error6);
  slot.pairs.clear();
  const FacetLess<L> less;
  for (std::size_t s = 0; s < slot.step_count; ++s) {
    const StepRecords& step = slot.steps[s];
    const std::uint64_t threshold = step.threshold;
    facets_checked_ += step.f.size();
    merged_.clear(), spill_run_.clear();
    auto settle = [&](const Facet& f) {  // a key with all this step's records folded
      if (std::uint64_t(f.v[0]) >= threshold)
        merged_.push_back(f);
      else if (std::uint64_t(f.v[0]) < facet_spill_min_)
        final_facet(f);
      else
        spill_run_.push_back(f);  // a spilled run may hold the same key
    };
    Facet key{};
    bool any = false;
    merge_visit<Facet>(live_.records(), step.f, less, [&](const Facet& r) {
      if (any && same_key(key, r)) return combine(key, r, slot.pairs);
      if (any) settle(key);
      key = r, any = true;
    });
    if (any) settle(key);
    if (!spill_run_.empty()) facet_spill_->push_sorted_run(std::span<Facet>(spill_run_));
    live_.replace(merged_);
    retire_facets(threshold);  // nothing below it is left: the peak, the budget, the hull edges
    if (sampled_) continue;
    merged_e_.clear(), spill_run_e_.clear();
    Edge last{};
    any = false;
    merge_visit<Edge>(live_e_.records(), step.e, std::less<Edge>(), [&](const Edge& e) {
      if (any && e == last) return;
      last = e, any = true;
      if (edge_u(e) >= threshold)
        merged_e_.push_back(e);
      else if (edge_u(e) < edge_spill_min_)
        ++edges_;
      else
        spill_run_e_.push_back(e);
    });
    if (!spill_run_e_.empty()) edge_spill_->push_sorted_run(std::span<Edge>(spill_run_e_));
    live_e_.replace(merged_e_);
    merge_edges(threshold);
  }
}

// The sorted facet and edge records of tets [lo, hi) of a frame (canon, flags: from
// tet lo on), on one thread: by lower stars (lower_stars.hpp) when the tets come in
// order of their smallest labels and their keys span few labels, as in every frame of
// `tetstream run`; else by sorting them all. A = the three facets (edges) through the
// tet's smallest label, B = the rest (records.hpp).
template <class L>
void Engine<L>::build_step(Scratch& w, StepRecords& out, const L* canon, const std::uint8_t* flags, std::size_t lo,
                           std::size_t hi, std::uint64_t first_ordinal, bool sorted_by_min) {
  const std::size_t n = hi - lo;
  // The labels' range: keys relative to its bottom sort in fewer radix digits; and
  // the reach of most tets (width[w]: tets whose labels lie within 2^w of it).
  std::uint64_t base = ~0ull, top = 0, last_min = 0;
  for (std::size_t i = 0; i < n; ++i)
    if (!(flags[i] & 2)) base = std::min<std::uint64_t>(base, canon[4 * i]);
  std::array<std::size_t, 65> width{};
  std::size_t good = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (flags[i] & 2) continue;  // broken: no records
    const L* s = canon + 4 * i;
    top = std::max<std::uint64_t>(top, s[3]);
    last_min = std::max<std::uint64_t>(last_min, s[0]);
    ++width[std::size_t(std::bit_width(std::uint64_t(s[3]) - base))], ++good;
  }
  const int bits = base <= top ? std::max(1, int(std::bit_width(top - base))) : 1;
  int near = 1;
  for (std::size_t within = width[0] + width[1]; near < bits && within < good - good / 128;)
    within += width[std::size_t(++near)];
  // Records keyed at or above upper_ belong to a later rank (hand_over_front made them).
  auto keep_facet = [&](const Facet& f) {
    return std::uint64_t(f.v[0]) < upper_ && facet_sampled(f.v[0], f.v[1], f.v[2]);
  };
  if (sorted_by_min && good > 0 && near < 40 && n < (std::size_t(1) << 30)) {
    // The keys of all but the long tets' records, and every smallest label.
    const std::uint64_t span = std::max(std::uint64_t(1) << near, last_min - base + 1);
    if (span <= lower_star_span_cap(step_tets_)) {
      if (w.a.capacity()) w.a = {}, w.b = {}, w.tmp = {}, w.far = {}, w.ea = {}, w.eb = {}, w.etmp = {}, w.seen = {};
      lower_star_records(
          canon, flags, n, first_ordinal + lo, base, std::size_t(span), keep_facet,
          [&](L u) { return std::uint64_t(u) < upper_; }, !sampled_, w.stars, out.f, out.e);
      return;
    }
  }
  w.stars = {};  // the plan holds one way's buffers at a time (plan_memory())
  auto& a = w.a;
  auto& b = w.b;
  a.clear(), b.clear();
  a.reserve(3 * n), b.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (flags[i] & 2) continue;
    tet_facets(canon + 4 * i, first_ordinal + lo + i, flags[i] & 1, [&](const Facet& f, bool through_min) {
      if (keep_facet(f)) (through_min ? a : b).push_back(f);
    });
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
    sort_facets(a, w.tmp, w.far, base, bits, near);
  }
  sort_facets(b, w.tmp, w.far, base, bits, near);
  out.f.resize(a.size() + b.size());
  std::merge(a.begin(), a.end(), b.begin(), b.end(), out.f.begin(), less);

  out.e.clear();
  if (sampled_) return;
  auto& ea = w.ea;
  auto& eb = w.eb;
  ea.clear(), eb.clear();
  ea.reserve(3 * n), eb.reserve(3 * n);
  // The B edges repeat (an edge is in several tets of a step): a direct-mapped table of
  // the last ones emitted drops most repeats before the sort, which makes them unique
  // anyway. Cleared every step, so the step's records do not depend on what the table
  // saw before (and the step's union is the same with or without it).
  w.seen.assign(std::size_t(1) << kSeenBits, make_edge(L(0), L(0)));  // no edge has u == v
  Edge* seen = w.seen.data();
  for (std::size_t i = 0; i < n; ++i) {
    if (flags[i] & 2) continue;
    tet_edges(canon + 4 * i, [&](L u, L v, bool through_min) {
      if (std::uint64_t(u) >= upper_) return;
      const Edge e = make_edge(u, v);
      if (through_min) {
        ea.push_back(e);
        return;
      }
      Edge& slot = seen[edge_slot(u, v, kSeenBits)];
      if (slot == e) return;
      slot = e;
      eb.push_back(e);
    });
  }
  if (sorted_by_min) {
    for (std::size_t g = 0; g < ea.size();) {
      std::size_t e = g + 1;
      while (e < ea.size() && edge_u(ea[e]) == edge_u(ea[g])) ++e;
      std::sort(ea.begin() + std::ptrdiff_t(g), ea.begin() + std::ptrdiff_t(e));
      g = e;
    }
  } else {
    sort_edges(ea, w.etmp, base, bits);
  }
  sort_edges(eb, w.etmp, base, bits);
  ea.erase(std::unique(ea.begin(), ea.end()), ea.end());
  eb.erase(std::unique(eb.begin(), eb.end()), eb.end());
  out.e.resize(ea.size() + eb.size());
  out.e.erase(std::set_union(ea.begin(), ea.end(), eb.begin(), eb.end(), out.e.begin()), out.e.end());
}
