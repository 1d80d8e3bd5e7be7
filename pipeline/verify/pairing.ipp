// Facet pairing and local Delaunay; the open facets and edges, retired or spilled (members of Engine,
// pipeline/verify/engine.hpp; compiled in engine.cpp). Included once, by engine.cpp, inside namespace
// tetstream::pipeline::verify_engine.

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
  constexpr std::size_t kAhead = 8;  // pairs whose points are asked for ahead of their test
  for (std::size_t i = 0; i < checks.size(); ++i) {
    if (i + kAhead < checks.size()) {
      const PairCheck& a = checks[i + kAhead];
      xyz_.prefetch(a.v[0]), xyz_.prefetch(a.v[1]), xyz_.prefetch(a.v[2]);
      xyz_.prefetch(a.dpos), xyz_.prefetch(a.dneg);
    }
    const PairCheck& c = checks[i];
    const int s = insphere_sos(c.v[0], c.v[1], c.v[2], c.dpos, c.dneg);
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
  const std::span<Facet> open = live_.records();
  const auto cut =
      std::partition_point(open.begin(), open.end(), [&](const Facet& f) { return std::uint64_t(f.v[0]) < threshold; });
  const auto spill_from =
      std::partition_point(open.begin(), cut, [&](const Facet& f) { return std::uint64_t(f.v[0]) < facet_spill_min_; });
  for (auto it = open.begin(); it != spill_from; ++it) final_facet(*it);
  if (spill_from != cut) facet_spill_->push_sorted_run(std::span<Facet>(&*spill_from, std::size_t(cut - spill_from)));
  live_.retire_front(std::size_t(cut - open.begin()));
  rep_.peak_open_facets = std::max<std::uint64_t>(rep_.peak_open_facets, live_.size());
  if (live_.size() * sizeof(Facet) > live_facet_budget_) {
    facet_spill_min_ = std::min<std::uint64_t>(facet_spill_min_, live_.records().front().v[0]);
    facet_spill_->push_sorted_run(live_.records());
    live_.release();
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
  const BoundedDet<long double> v = volume6(origin_, P(a), P(b), P(c));
  hull_volume6_.add(v.value);
  hull_error6_.add(v.error);
  const std::uint64_t ord = f.x & kPayload;
  auto edge = [&](L p, L q, L w) {
    hull_edges_batch_.push_back(p < q ? HullEdge{p, q, w, ord | kSide} : HullEdge{q, p, w, ord});
  };
  edge(a, b, c), edge(b, c, a), edge(c, a, b);
}

template <class L>
void Engine<L>::merge_edges(std::uint64_t threshold) {
  const std::span<Edge> open = live_e_.records();
  const auto cut = std::partition_point(open.begin(), open.end(), [&](const Edge& e) { return edge_u(e) < threshold; });
  const auto spill_from =
      std::partition_point(open.begin(), cut, [&](const Edge& e) { return edge_u(e) < edge_spill_min_; });
  edges_ += std::uint64_t(spill_from - open.begin());
  if (spill_from != cut) edge_spill_->push_sorted_run(std::span<Edge>(&*spill_from, std::size_t(cut - spill_from)));
  live_e_.retire_front(std::size_t(cut - open.begin()));
  rep_.peak_open_edges = std::max<std::uint64_t>(rep_.peak_open_edges, live_e_.size());
  if (live_e_.size() * sizeof(Edge) > live_edge_budget_) {
    edge_spill_min_ = std::min<std::uint64_t>(edge_spill_min_, edge_u(live_e_.records().front()));
    edge_spill_->push_sorted_run(live_e_.records());
    live_e_.release();
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
