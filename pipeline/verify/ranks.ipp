// A distributed job's hand-overs (members of Engine, pipeline/verify/engine.hpp; compiled in engine.cpp).
// Included once, by engine.cpp, inside namespace tetstream::pipeline::verify_engine.
//
// Rank r checks the frames of its run (split.hpp) and owns the keys [lower_, upper_).
// Its tets' labels are >= lower_ (a frame's labels are >= its declared smallest label),
// so no record it makes has a key below lower_; some have keys >= upper_ (a tet of a
// late frame reaching into later ranks' labels: the front). Those records are made
// before the pass, by a pre-pass over the frames that can reach them (max_label >=
// upper_), and sent to their owners, which fold them before their own pass; the pass
// itself skips them (build_step). So every key is folded on one rank, from all its
// records, in the order one process folds them (replay_front), before any later tet
// touches it, and finalized when one process would.
//
// Why a pre-pass rather than holding the owner's keys open until the earlier ranks are
// done (the first plan): the frame index's max_label bounds how far a frame reaches,
// but one long tet (on the hull, say) sets it, and in tetstream's own outputs the
// earlier ranks' max_label reaches nearly every label of the later ranks: the held band
// would be almost the whole range. The pre-pass decodes only frames whose max_label
// reaches a later rank, once more (about a tenth of verify's time a frame).

// The front: this rank's records keyed in later ranks' labels, to their owners; theirs
// for this rank's keys, folded here.
template <class L>
void Engine<L>::hand_over_front(const std::vector<std::size_t>& order, const std::vector<std::uint64_t>& position) {
  const std::size_t ranks = std::size_t(comm_.size()), me = std::size_t(comm_.rank());
  std::vector<std::vector<Facet>> facets_to(ranks);
  std::vector<std::vector<Edge>> edges_to(ranks);
  const auto t0 = Clock::now();
  std::size_t decoded = 0;
  together(comm_, [&] {
    if (upper_ == ~0ull) return;  // no later rank owns a label
    std::vector<L> labels;
    std::vector<std::uint8_t> flags;
    try {
      for (std::size_t j = split_.first[me]; j < split_.first[me + 1]; ++j) {
        const std::size_t k = order[j];
        if (src_.batch(k).max_label < upper_) continue;
        src_.read_batch(k, labels);
        ++decoded;
        canonicalize(k, labels, flags, false, true, [](std::size_t, std::uint64_t, const L*) {});
        const std::uint64_t first_tet = src_.batch(k).first_tet;
        for (std::size_t i = 0; i < flags.size(); ++i) {
          const L* s = labels.data() + 4 * i;
          if ((flags[i] & 2) || std::uint64_t(s[3]) < upper_) continue;
          tet_facets(s, first_tet + i, flags[i] & 1, [&](const Facet& f, bool) {
            if (std::uint64_t(f.v[0]) >= upper_ && facet_sampled(f.v[0], f.v[1], f.v[2]))
              facets_to[std::size_t(split_.owner(f.v[0]))].push_back(f);
          });
          if (!sampled_)
            tet_edges(s, [&](L u, L v, bool) {
              if (std::uint64_t(u) >= upper_) edges_to[std::size_t(split_.owner(u))].push_back(make_edge(u, v));
            });
        }
        check_interrupted();
      }
    } catch (...) {
      // The pass meets this failure again at this frame, or another at an earlier one
      // first, as one process would; it rethrows this one if it does not (front_error_).
      // What was collected goes out: the job stops after the pass.
      front_error_ = std::current_exception();
    }
  });
  std::uint64_t sent = 0;
  for (const auto& v : facets_to) sent += v.size();
  spdlog::debug("verify: rank {}: front of {} facet records from {} of its {} frames in {:.2f}s", me, sent, decoded,
                split_.first[me + 1] - split_.first[me], since(t0));
  std::vector<Facet> front = exchange_records(comm_, facets_to);
  facets_to = {};
  std::vector<Edge> edges = exchange_records(comm_, edges_to);
  edges_to = {};
  together(comm_, [&] {
    replay_front(front, order, position);
    std::sort(edges.begin(), edges.end());
    edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
    live_e_.replace(edges);
  });
}

// Folds the received records as one process folds them: one process meets a key's
// records step by step (a step: step_tets_ tets of a frame, frames in `order`), each
// step's records merged with the key's open record in FacetLess order, the open one
// first on a tie, then folded (combine()). The received records come from frames
// before this rank's; each key's are replayed in that order, so the open record this
// rank starts from, the violations logged and the pairs tested are one process's.
template <class L>
void Engine<L>::replay_front(std::vector<Facet>& front, const std::vector<std::size_t>& order,
                             const std::vector<std::uint64_t>& position) {
  facets_checked_ += front.size();
  if (front.empty()) return;
  // A record's step, from its ordinal: its frame (frames in stored order start at
  // increasing ordinals), that frame's place in `order`, the step within the frame.
  std::vector<std::uint64_t> first_tets(order.size());
  for (std::size_t k = 0; k < order.size(); ++k) first_tets[k] = src_.batch(k).first_tet;
  struct Item {
    std::uint64_t position, step;
    Facet f;
  };
  std::vector<Item> items(front.size());
  for (std::size_t i = 0; i < front.size(); ++i) {
    const std::uint64_t ordinal = front[i].x & kPayload;
    const std::size_t k =
        std::size_t(std::upper_bound(first_tets.begin(), first_tets.end(), ordinal) - first_tets.begin()) - 1;
    items[i] = Item{position[k], (ordinal - first_tets[k]) / step_tets_, front[i]};
  }
  front = {};
  const FacetLess<L> less;
  std::sort(items.begin(), items.end(), [&](const Item& a, const Item& b) {
    if (!same_key(a.f, b.f)) return less(a.f, b.f);
    if (a.position != b.position) return a.position < b.position;
    if (a.step != b.step) return a.step < b.step;
    return less(a.f, b.f);
  });
  std::vector<PairCheck> checks;
  std::vector<Facet> open, step, merged;
  live_.clear();
  for (std::size_t g = 0; g < items.size();) {
    open.clear();
    std::size_t e = g;
    while (e < items.size() && same_key(items[e].f, items[g].f)) {
      step.clear();
      const std::size_t s = e;
      for (; e < items.size() && same_key(items[e].f, items[s].f) && items[e].position == items[s].position &&
             items[e].step == items[s].step;
           ++e)
        step.push_back(items[e].f);
      merged.resize(open.size() + step.size());
      std::merge(open.begin(), open.end(), step.begin(), step.end(), merged.begin(), less);
      merged.resize(fold_equal_keys(merged.data(), merged.size(), checks));
      std::swap(open, merged);
    }
    live_.push_back(open.front());  // one record: the key's state after the earlier ranks' frames
    g = e;
  }
  check_pairs(checks);
  rep_.peak_open_facets = std::max<std::uint64_t>(rep_.peak_open_facets, live_.size());
}

// The boundary edges this rank found, each to the rank that owns its smaller label,
// where finish_hull() groups them.
template <class L>
void Engine<L>::hand_over_hull_edges() {
  const std::size_t ranks = std::size_t(comm_.size());
  std::vector<std::vector<HullEdge>> to(ranks);
  together(comm_, [&] {
    hull_sorter_->merge([&](std::span<const HullEdge> batch) {
      for (const HullEdge& h : batch) to[std::size_t(split_.owner(h.u))].push_back(h);
    });
    rep_.spilled_records += hull_sorter_->stats().runs_written ? hull_sorter_->stats().records_pushed : 0;
    rep_.spill_bytes += hull_sorter_->stats().bytes_written;
    hull_sorter_ = std::make_unique<ExternalSorter<HullEdge, HullEdgeLess<L>>>(hull_sort_options_);
  });
  const std::vector<HullEdge> mine = exchange_records(comm_, to);
  to = {};
  together(comm_, [&] { hull_sorter_->push(std::span<const HullEdge>(mine)); });
}

// The bits of `bits` in other ranks' labels, to them (a rank's tets set bits of labels
// at or above its own, never below): afterwards each rank's bits of its own labels
// are those of the whole job.
template <class L>
void Engine<L>::hand_over_bits(Bitmap& bits) {
  if (comm_.size() == 1) return;
  const std::size_t ranks = std::size_t(comm_.size());
  auto words_of = [&](std::size_t r) {  // the words holding rank r's labels
    const std::uint64_t lo = std::min(split_.low[r], n_), hi = std::min(split_.low[r + 1], n_);
    return std::pair<std::uint64_t, std::uint64_t>{lo / 64, lo < hi ? (hi + 63) / 64 : lo / 64};
  };
  std::vector<std::vector<std::uint64_t>> to(ranks);
  const std::vector<std::uint64_t>& w = bits.words();
  for (std::size_t r = std::size_t(comm_.rank()) + 1; r < ranks; ++r) {
    const auto [a, b] = words_of(r);
    to[r].assign(w.begin() + std::ptrdiff_t(a), w.begin() + std::ptrdiff_t(b));
  }
  const std::vector<std::uint64_t> got = exchange_records(comm_, to);
  // From every earlier rank (and from no other), each sent the same words: ours.
  const auto [a, b] = words_of(std::size_t(comm_.rank()));
  std::vector<std::uint64_t>& mine = bits.words();
  for (std::size_t at = 0; at < got.size(); ++at)
    mine[std::size_t(a + at % std::max<std::uint64_t>(1, b - a))] |= got[at];
}

// This rank's totals as bytes, for rank 0: counters, violations, volumes.
template <class L>
std::string Engine<L>::partial_totals() {
  std::string out;
  auto put = [&](std::uint64_t v) { out.append(reinterpret_cast<const char*>(&v), sizeof v); };
  auto put_text = [&](const std::string& s) {
    put(s.size());
    out += s;
  };
  for (std::uint64_t v :
       {good_tets_, interior_, boundary_, bad_facets_, edges_, hull_edges_, facets_checked_, tets_checked_,
        orient_tests_.load(), insphere_tests_.load(), hull_tests_.load(), vertices_, hull_vertices_,
        rep_.peak_open_facets, rep_.peak_open_edges, rep_.spilled_records, rep_.spill_bytes, rep_.memory_planned})
    put(v);
  put_text(tet_volume6_.bytes());
  put_text(hull_volume6_.bytes());
  put_text(tet_error6_.bytes());
  put_text(hull_error6_.bytes());
  VerifyReport r;
  log_.into(r);
  for (std::uint64_t c : r.counts) put(c);
  put(r.listed.size());
  for (const auto& l : r.listed) {
    put(std::uint64_t(l.kind));
    put(l.where);
    put_text(l.text);
  }
  return out;
}

// On rank 0: the other ranks' totals added to this rank's (ranks in order).
template <class L>
void Engine<L>::merge_totals(const std::vector<std::string>& parts) {
  for (std::size_t p = 1; p < parts.size(); ++p) {
    const std::string& in = parts[p];
    std::size_t at = 0;
    auto get = [&] {
      std::uint64_t v = 0;
      if (at + sizeof v > in.size()) throw IoError("verify: a rank's totals are truncated");
      std::memcpy(&v, in.data() + at, sizeof v);
      at += sizeof v;
      return v;
    };
    auto get_text = [&] {
      const std::uint64_t n = get();
      if (n > in.size() - at) throw IoError("verify: a rank's totals are truncated");
      std::string s = in.substr(at, std::size_t(n));
      at += std::size_t(n);
      return s;
    };
    good_tets_ += get(), interior_ += get(), boundary_ += get(), bad_facets_ += get(), edges_ += get();
    hull_edges_ += get(), facets_checked_ += get(), tets_checked_ += get();
    orient_tests_ += get(), insphere_tests_ += get(), hull_tests_ += get();
    vertices_ += get(), hull_vertices_ += get();
    rep_.peak_open_facets = std::max(rep_.peak_open_facets, get());
    rep_.peak_open_edges = std::max(rep_.peak_open_edges, get());
    rep_.spilled_records += get(), rep_.spill_bytes += get();
    rep_.memory_planned = std::max(rep_.memory_planned, get());
    tet_volume6_.add(ExactSum::from_bytes(get_text()));
    hull_volume6_.add(ExactSum::from_bytes(get_text()));
    tet_error6_.add(ExactSum::from_bytes(get_text()));
    hull_error6_.add(ExactSum::from_bytes(get_text()));
    std::array<std::uint64_t, kViolationKinds> counts{};
    for (auto& c : counts) c = get();
    std::vector<VerifyReport::Listed> listed(static_cast<std::size_t>(get()));
    for (auto& l : listed) {
      l.kind = Violation(int(get()));
      l.where = get();
      l.text = get_text();
    }
    log_.merge(counts, listed);
  }
}
