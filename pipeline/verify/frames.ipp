// A frame's tets: storage, orientation, volume, and their facets and edges (members of Engine, pipeline/verify/engine.hpp; compiled in engine.cpp).
// Included once, by engine.cpp, inside namespace tetstream::pipeline::verify_engine.

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
      const PointCoords::Point p0 = P(g[0]), p1 = P(g[1]), p2 = P(g[2]), p3 = P(g[3]);
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

