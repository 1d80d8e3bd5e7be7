// A frame's tets: storage, orientation, volume, and their facets and edges (members of Engine,
// pipeline/verify/engine.hpp; compiled in engine.cpp). Included once, by engine.cpp, inside namespace
// tetstream::pipeline::verify_engine.

template <class L>
template <class OnGood>
void Engine<L>::canonicalize(std::size_t k, std::vector<L>& labels, std::vector<std::uint8_t>& flags, bool log_storage,
                             OnGood&& on_good) {
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
#pragma omp parallel for schedule(dynamic, 4) reduction(|| : below_min, above_max)
  for (std::int64_t c = 0; c < chunks; ++c) {
    const std::size_t lo = std::size_t(c) * kChunk, hi = std::min(t, lo + kChunk);
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

template <class L>
void Engine<L>::process_frame(std::size_t k, std::vector<L>& labels, std::uint64_t future_min) {
  const VerifySource::Batch b = src_.batch(k);
  const std::size_t t = labels.size() / 4;
  std::vector<std::uint8_t> flags;
  const std::size_t threads = std::size_t(std::max(1, omp_get_max_threads()));
  std::vector<std::uint64_t> checked(threads, 0), good(threads, 0);
  if (thread_volume_.size() < threads) thread_volume_.resize(threads);
  if (thread_error_.size() < threads) thread_error_.resize(threads);
  canonicalize(k, labels, flags, true, [&](std::size_t, std::uint64_t ordinal, const L* g) {
    const std::size_t me = std::size_t(omp_get_thread_num());
    ++good[me];
    for (int j = 0; j < 4; ++j) used_.set(g[j]);
    const PointCoords::Point p0 = P(g[0]), p1 = P(g[1]), p2 = P(g[2]), p3 = P(g[3]);
    const BoundedDet<long double> v = volume6(p0, p1, p2, p3);
    thread_volume_[me].add(std::fabs(v.value));
    thread_error_[me].add(v.error);
    if (tet_sampled(ordinal)) {
      ++checked[me];
      const int o = core::orient3d(p0, p1, p2, p3);
      if (o <= 0)
        log_.add(Violation::kOrientation, ordinal, [&] {
          return tet_text(ordinal, g[0], g[1], g[2], g[3]) +
                 (o == 0 ? ": flat (orient3d = 0)" : ": negatively oriented (orient3d = -1)");
        });
    }
  });
  for (std::size_t i = 0; i < threads; ++i) {
    tets_checked_ += checked[i], orient_tests_ += checked[i];
    good_tets_ += good[i];
  }

  // Steps: after each, keys below the smallest label still to come (in later steps
  // of this frame or in later frames) are final.
  const std::size_t step = step_tets_;
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
void Engine<L>::process_step(const L* canon, const std::uint8_t* flags, std::size_t count, std::uint64_t first_ordinal,
                             bool sorted_by_min, std::uint64_t threshold) {
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
    in.emplace_back(live_.records());
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
    const std::size_t n =
        merge_ranges(in, merged_, less, key_less, chunk_sizes_, [&](std::size_t r, Facet* first, std::size_t m) {
          auto& cc = chunk_checks_[r];
          cc.clear();
          const std::size_t w = fold_equal_keys(first, m, cc);
          check_pairs(cc);
          return w;
        });
    merged_.resize(n);
    live_.replace(merged_);
    retire_facets(threshold);
  }

  // ---- edges (not in a sample): union of the slices and the open set.
  if (!sampled_) {
    std::vector<std::span<const Edge>> in;
    in.emplace_back(live_e_.records());
    for (int p = 0; p < threads; ++p) in.emplace_back(parts_[std::size_t(p)].e);
    const std::less<Edge> less;
    const std::size_t n = merge_ranges(
        in, merged_e_, less, less, chunk_sizes_,
        [](std::size_t, Edge* first, std::size_t m) { return std::size_t(std::unique(first, first + m) - first); });
    merged_e_.resize(n);
    live_e_.replace(merged_e_);
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
  // Records keyed at or above upper_ belong to a later rank (hand_over_front made them).
  for (std::size_t i = lo; i < hi; ++i) {
    if (flags[i] & 2) continue;  // broken: no facets
    tet_facets(canon + 4 * i, first_ordinal + i, flags[i] & 1, [&](const Facet& f, bool through_min) {
      if (std::uint64_t(f.v[0]) < upper_ && facet_sampled(f.v[0], f.v[1], f.v[2])) (through_min ? a : b).push_back(f);
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
    tet_edges(canon + 4 * i, [&](L u, L v, bool through_min) {
      if (std::uint64_t(u) < upper_) (through_min ? ea : eb).push_back(make_edge(u, v));
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
    sort_edges(ea, part.etmp);
  }
  sort_edges(eb, part.etmp);
  ea.erase(std::unique(ea.begin(), ea.end()), ea.end());
  eb.erase(std::unique(eb.begin(), eb.end()), eb.end());
  part.e.resize(ea.size() + eb.size());
  part.e.erase(std::set_union(ea.begin(), ea.end(), eb.begin(), eb.end(), part.e.begin()), part.e.end());
}

// A = the three facets through s[0], B = the fourth. Facet opposite s_i, written
// (others sorted, s_i), has the orientation of (s0..s3) times (-1)^(3-i), and
// (s0..s3) has the tet's times (-1)^parity; kSide when that is positive.
template <class L>
template <class Emit>
void Engine<L>::tet_facets(const L* s, std::uint64_t ordinal, int parity, Emit&& emit) {
  auto side = [&](int opp) { return ((parity + 3 - opp) & 1) == 0 ? kSide : 0; };
  emit(Facet{{s[0], s[1], s[2]}, s[3], ordinal | side(3)}, true);
  emit(Facet{{s[0], s[1], s[3]}, s[2], ordinal | side(2)}, true);
  emit(Facet{{s[0], s[2], s[3]}, s[1], ordinal | side(1)}, true);
  emit(Facet{{s[1], s[2], s[3]}, s[0], ordinal | side(0)}, false);
}

template <class L>
template <class Emit>
void Engine<L>::tet_edges(const L* s, Emit&& emit) {
  emit(s[0], s[1], true), emit(s[0], s[2], true), emit(s[0], s[3], true);
  emit(s[1], s[2], false), emit(s[1], s[3], false), emit(s[2], s[3], false);
}
