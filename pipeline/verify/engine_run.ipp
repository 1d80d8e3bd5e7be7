// The memory plan, the points, the frame loop and the radix sorts (members of Engine, pipeline/verify/engine.hpp;
// compiled in engine.cpp). Included once, by engine.cpp, inside namespace tetstream::pipeline::verify_engine.

template <class L>
void Engine<L>::sort_facets(std::vector<Facet>& v, std::vector<Facet>& tmp, std::vector<Facet>& far, std::uint64_t base,
                            int b, int near) const {
  auto passes = [](int bits) { return (bits + 10) / 11; };  // radix_sort's 11-bit digits
  const int full = 3 * b <= 64 ? passes(3 * b) : 3 * passes(b);
  if (near < b && 3 * near <= 64 && passes(3 * near) < full) {
    // Most records lie within 2^near labels of base (a step's tets are a few slabs
    // thick); the few that reach further (long tets on the hull or across a hollow)
    // are sorted apart and merged back: FacetLess orders records of equal labels by
    // their ordinals, as the stable radix sort leaves them.
    far.clear();
    std::size_t kept = 0;
    for (const Facet& f : v)
      if ((std::uint64_t(f.v[2]) - base) >> near)
        far.push_back(f);
      else
        v[kept++] = f;
    v.resize(kept);
    radix_sort(v.data(), v.size(), tmp, 3 * near, [near, base](const Facet& f) {
      return (std::uint64_t(f.v[0]) - base) << (2 * near) | (std::uint64_t(f.v[1]) - base) << near |
             (std::uint64_t(f.v[2]) - base);
    });
    if (far.empty()) return;
    const FacetLess<L> less;
    std::sort(far.begin(), far.end(), less);
    tmp.resize(v.size() + far.size());
    std::merge(v.begin(), v.end(), far.begin(), far.end(), tmp.begin(), less);
    std::swap(v, tmp);
  } else if (3 * b <= 64) {
    radix_sort(v.data(), v.size(), tmp, 3 * b, [b, base](const Facet& f) {
      return (std::uint64_t(f.v[0]) - base) << (2 * b) | (std::uint64_t(f.v[1]) - base) << b |
             (std::uint64_t(f.v[2]) - base);
    });
  } else {
    for (int j = 2; j >= 0; --j)
      radix_sort(v.data(), v.size(), tmp, b, [j, base](const Facet& f) { return std::uint64_t(f.v[j]) - base; });
  }
}

template <class L>
void Engine<L>::sort_edges(std::vector<Edge>& v, std::vector<Edge>& tmp, std::uint64_t base, int b) const {
  if constexpr (sizeof(L) == 4) {
    radix_sort(v.data(), v.size(), tmp, 2 * b,
               [b, base](std::uint64_t e) { return ((e >> 32) - base) << b | ((e & 0xFFFFFFFFu) - base); });
  } else if (2 * b <= 64) {
    radix_sort(v.data(), v.size(), tmp, 2 * b, [b, base](const Edge& e) { return (e.u - base) << b | (e.v - base); });
  } else {
    radix_sort(v.data(), v.size(), tmp, b, [base](const Edge& e) { return e.v - base; });
    radix_sort(v.data(), v.size(), tmp, b, [base](const Edge& e) { return e.u - base; });
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

// The points' resident window. The pass reads the points of the frames in flight,
// which lie within about a frame's reach above the frames' smallest labels (a frame's
// tets are a few slabs thick), and its pairs' tests reach about as far below;
// release_points_outside() hands back the pages further below, a slice at a time,
// and now and then those far above.
// A frame's reach: the labels above its smallest that 99% of its tets' vertices take,
// the largest of up to 9 frames decoded here, spread over the file (a few long tets
// stretch a frame's declared range far beyond it: 10^8 uniform points, declared ranges
// of 5.0 M labels (median) and up to 96 M, 95% of the vertices within 0.34 M); the
// median declared range where no frame decodes (a damaged one: the pass reports it).
// Planned: twice the reach below the frame being consumed and twice the reach and the
// frames in flight (as many as threads and one, at twice the median step between
// frames' smallest labels) above it, and two slices. Returns the bytes.
template <class L>
std::size_t Engine<L>::plan_point_window() {
  const std::size_t stride = src_.points().stride, frames = src_.batch_count();
  std::vector<std::uint64_t> spans(frames), mins(frames), steps;
  for (std::size_t k = 0; k < frames; ++k) {
    const VerifySource::Batch b = src_.batch(k);
    mins[k] = b.min_label;
    spans[k] = b.max_label >= b.min_label ? std::min(n_, b.max_label - b.min_label + 1) : n_;
  }
  std::sort(mins.begin(), mins.end());
  for (std::size_t k = 1; k < frames; ++k) steps.push_back(mins[k] - mins[k - 1]);
  auto median = [](std::vector<std::uint64_t>& v) -> std::uint64_t {
    if (v.empty()) return 0;
    std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(v.size() / 2), v.end());
    return v[v.size() / 2];
  };
  const std::uint64_t span = median(spans), step = median(steps);
  std::sort(spans.begin(), spans.end());
  auto quantile = [&](double q) { return spans.empty() ? 0 : spans[std::size_t(q * double(spans.size() - 1))]; };
  std::uint64_t reach = 0;
  std::size_t decoded = 0;
  std::vector<L> labels;
  std::vector<std::uint64_t> above;
  for (std::size_t i = 1; i <= 9 && frames > 0; ++i) {
    const std::size_t k = std::min(frames - 1, i * frames / 10);
    try {
      src_.read_batch(k, labels);
    } catch (const std::exception&) {
      continue;
    }
    if (labels.empty()) continue;
    const std::uint64_t lo = src_.batch(k).min_label;
    above.resize(labels.size());
    for (std::size_t j = 0; j < labels.size(); ++j)
      above[j] = std::uint64_t(labels[j]) > lo ? std::min<std::uint64_t>(labels[j] - lo, n_) : 0;
    const auto at = above.begin() + std::ptrdiff_t(above.size() * 99 / 100);
    std::nth_element(above.begin(), at, above.end());
    reach = std::max(reach, *at + 1), ++decoded;
  }
  reach = decoded > 0 ? std::min(reach, span) : span;
  const std::uint64_t threads = std::uint64_t(std::max(1, omp_get_max_threads()));
  release_slice_labels_ = std::max<std::uint64_t>(1, (std::uint64_t(4) << 20) / std::max<std::size_t>(1, stride));
  behind_labels_ = 2 * reach;
  ahead_labels_ = 2 * reach + 2 * (threads + 1) * step;
  const std::uint64_t window = std::min(n_, behind_labels_ + ahead_labels_ + 2 * release_slice_labels_);
  spdlog::debug(
      "verify: points in place, {} bytes a record; frames declare {} labels (median; 90%: {}, 99%: {}, widest: "
      "{}), reach {} (99% of the vertices, {} frames decoded), step {}; window {} labels",
      stride, span, quantile(0.9), quantile(0.99), quantile(1), reach, decoded, step, window);
  return std::size_t(window) * stride;
}

template <class L>
void Engine<L>::plan_memory() {
  const std::size_t points = plan_point_window() + used_.bytes() + hull_used_.bytes();
  // A frame: two label buffers (one decoding) and flags. A step, per tet: the slices'
  // A, B, merged and radix buffers (11 facets, 15 edges), the merged copy (4 facets,
  // 6 edges) and up to 2 pair checks.
  std::size_t max_frame = 0;
  for (std::size_t k = 0; k < src_.batch_count(); ++k)
    max_frame = std::max<std::size_t>(max_frame, std::size_t(src_.batch(k).tet_count));
  auto scratch_of = [&](std::size_t step) {
    return max_frame * (2 * 4 * sizeof(L) + 1) +
           step * (15 * sizeof(Facet) + 21 * sizeof(Edge) + 2 * sizeof(PairCheck));
  };
  // The largest step (up to batch_tets) whose scratch leaves the open sets at least as
  // much as it takes; never below 2^14 tets or batch_tets. Every rank plans the same
  // step (same frames, same --memory), and the step does not change the report.
  // What the plan divides: --memory less the process's own reserve (its code, the
  // libraries, the threads' stacks, the allocator's slack; the code and the libraries
  // alone are 12-13 MiB of file-backed pages in /proc/PID/status's RssFile).
  const std::size_t reserve = std::size_t(MemoryBudget::process_reserve(opt_.memory_bytes));
  const std::size_t budget = std::size_t(opt_.memory_bytes) - reserve;
  step_tets_ = std::max<std::size_t>(1, std::min<std::size_t>(max_frame, opt_.batch_tets));
  const std::size_t floor_step = std::min<std::size_t>(step_tets_, std::size_t(1) << 14);
  while (step_tets_ / 2 >= floor_step && points + 2 * scratch_of(step_tets_) > budget) step_tets_ /= 2;
  // The pass's frames in flight (run()): each slot holds a frame's records (4 facets,
  // at most 6 edges a tet) and its pairs (at most 2 a tet); each frame being prepared
  // (one a thread, at most one a slot) its labels and flags and one step's building
  // buffers (7 facets and 9 edges a tet for a full sort; by lower stars a facet, 3
  // labels and 9 edges a tet and counts over the keys' span; one of the two
  // at a time, build_step(); and a table of edges); the ordered merge, the merged copy
  // of one step. As many slots as threads and one, while the scratch takes at most half of
  // what the points leave (the open sets the rest); at least one.
  const std::size_t threads = std::size_t(std::max(1, omp_get_max_threads()));
  auto pass_scratch = [&](std::size_t slots) {
    const std::size_t slot = max_frame * (4 * sizeof(Facet) + 6 * sizeof(Edge) + 2 * sizeof(PairCheck));
    const std::size_t sorting = step_tets_ * (7 * sizeof(Facet) + 9 * sizeof(Edge));
    const std::size_t by_stars =
        step_tets_ * (sizeof(Facet) + 3 * sizeof(L) + 9 * sizeof(Edge)) + lower_star_span_cap(step_tets_) * 8;
    const std::size_t preparing =
        max_frame * (4 * sizeof(L) + 1) + std::max(sorting, by_stars) + (std::size_t(1) << kSeenBits) * sizeof(Edge);
    return slots * slot + std::min(slots, threads) * preparing + step_tets_ * (4 * sizeof(Facet) + 6 * sizeof(Edge));
  };
  slots_ = threads + 1;
  while (slots_ > 1 && points + 2 * pass_scratch(slots_) > budget) --slots_;
  const std::size_t scratch = pass_scratch(slots_);
  const std::size_t fixed = points + scratch;
  std::size_t rest = budget > fixed ? budget - fixed : 0;
  if (rest < (std::size_t(16) << 20)) {
    spdlog::warn(
        "verify: --memory {} leaves less than 16 MiB for the open facets beside the points and one batch "
        "({}); going over it",
        human_bytes(double(opt_.memory_bytes)), human_bytes(double(reserve + fixed)));
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
  rep_.memory_planned = reserve + fixed + rest;
  rep_.step_tets = step_tets_;
  spdlog::debug(
      "verify: memory: process {}, points {}, scratch {} (steps of {} tets, {} frames in flight), open facets {}, "
      "open edges {}, sorts {}",
      human_bytes(double(reserve)), human_bytes(double(points)), human_bytes(double(scratch)), step_tets_, slots_,
      human_bytes(double(live_facet_budget_)), human_bytes(double(live_edge_budget_)),
      human_bytes(double(sorter_budget_)));
}

template <class L>
void Engine<L>::load_points() {
  const auto t0 = Clock::now();
  xyz_.assign(src_.points());
  // One pass over the points, a chunk of 2^16 a thread at a time, each chunk's pages
  // handed back once read (the frames read them again, a window at a time): the
  // lexicographically smallest point, a vertex of the convex hull (the cones from it
  // over the hull facets then have non-negative volume: no cancellation), and whether
  // the volumes fit doubles (floats always do: magnitudes in [2^-149, 2^128]).
  constexpr std::uint64_t kChunk = 1 << 16;
  const std::size_t chunks = std::size_t((n_ + kChunk - 1) / kChunk);
  std::vector<std::uint64_t> best_of(chunks);
  std::vector<char> wide_of(chunks, 0);
  auto lex_less = [](const PointCoords::Point& p, const PointCoords::Point& b) {
    return p[0] < b[0] || (p[0] == b[0] && (p[1] < b[1] || (p[1] == b[1] && p[2] < b[2])));
  };
#pragma omp parallel for schedule(dynamic, 1)
  for (std::size_t c = 0; c < chunks; ++c) {
    const std::uint64_t first = std::uint64_t(c) * kChunk, end = std::min(n_, first + kChunk);
    std::uint64_t best = first;
    bool wide = false;
    for (std::uint64_t i = first; i < end; ++i) {
      const PointCoords::Point p = P(i);
      if (i > first && lex_less(p, P(best))) best = i;
      if (!xyz_.floats() && !wide) wide = !volume_fits_double(p, 1);
    }
    best_of[c] = best, wide_of[c] = wide;
    src_.release_points(first, end - first);
  }
  // The first smallest in label order, as one scan finds it.
  std::uint64_t best = 0;
  for (std::size_t c = 0; c < chunks; ++c)
    if (c == 0 || lex_less(P(best_of[c]), P(best))) best = best_of[c];
  if (n_ > 0) std::copy_n(P(best).c, 3, origin_);
  wide_volume_ = std::any_of(wide_of.begin(), wide_of.end(), [](char w) { return w != 0; });
  src_.release_points(0, n_);
  seconds_points_ = since(t0);
}

template <class L>
void Engine<L>::run() {
  const auto t0 = Clock::now();
  // Frames in order of their smallest label (frames are independent, so any order is
  // allowed, and this one retires keys soonest even when a writer appended a late
  // frame). later_min[j]: the smallest label of the frames after position j.
  // position[k]: where frame k comes in that order. The order is cut into the ranks'
  // runs (split.hpp); one process is the run of rank 0 of 1.
  const std::size_t frames = src_.batch_count();
  std::vector<std::size_t> order(frames);
  std::iota(order.begin(), order.end(), std::size_t(0));
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return src_.batch(a).min_label < src_.batch(b).min_label; });
  std::vector<std::uint64_t> later_min(frames + 1, ~0ull), position(frames), mins(frames), counts(frames);
  for (std::size_t j = frames; j-- > 0;) later_min[j] = std::min(later_min[j + 1], src_.batch(order[j]).min_label);
  for (std::size_t j = 0; j < frames; ++j) {
    position[order[j]] = j;
    mins[j] = src_.batch(order[j]).min_label;
    counts[j] = src_.batch(order[j]).tet_count;
  }
  split_ = split_frames(mins, counts, comm_.size());
  const std::size_t me = std::size_t(comm_.rank());
  lower_ = me == 0 ? 0 : split_.low[me];
  upper_ = split_.low[me + 1];
  const std::size_t first = split_.first[me], last = split_.first[me + 1];

  together(comm_, [&] {
    tmp_parent_ = opt_.tmpdir;
    if (tmp_parent_.empty()) {
      const char* env = std::getenv("TMPDIR");
      tmp_parent_ = env && *env ? std::string(env) : src_.directory();
      if (tmp_parent_.empty()) tmp_parent_ = ".";
    }
    plan_memory();
    load_points();

    auto make_dir = [this] { return make_tmpdir(); };
    ExternalSortOptions o;
    o.memory_bytes = sorter_budget_;
    o.make_dir = make_dir;
    o.name = "facets";
    facet_spill_ = std::make_unique<ExternalSorter<Facet, FacetLess<L>>>(o);
    o.name = "edges";
    edge_spill_ = std::make_unique<ExternalSorter<Edge, std::less<Edge>>>(o);
    edge_spill_->set_reducer(
        [](Edge* first, std::size_t n) { return std::size_t(std::unique(first, first + n) - first); });
    o.name = "hull-edges";
    o.memory_bytes = std::max<std::size_t>(sorter_budget_ / 5, std::size_t(4) << 20);
    hull_sort_options_ = o;
    hull_sorter_ = std::make_unique<ExternalSorter<HullEdge, HullEdgeLess<L>>>(o);
  });
  // The records of this rank's tets whose keys later ranks own, to them; theirs for
  // this rank's keys, folded here first (a collective step: every rank takes part).
  if (comm_.size() > 1) hand_over_front(order, position);

  // Pass over this rank's frames: a pipeline on every thread (engine.hpp, Slot). A
  // thread takes, in this order of preference: the consumption of the next frame in
  // order when it is prepared (the merges with the open sets; one thread at a time),
  // else the insphere tests of a consumed frame's pairs, else the preparation of the
  // next frame when a slot and a scratch are free (decode, the tets' checks, the steps'
  // sorted records: several threads at once), else it waits. Frame j's slot is frame
  // j - slots_'s, free once that one is consumed and its pairs tested. A failure stops
  // the pass at the first failing frame in that order, as a loop over the frames would.
  together(comm_, [&] {
    const auto t1 = Clock::now();
    std::uint64_t my_tets = 0;
    for (std::size_t j = first; j < last; ++j) my_tets += src_.batch(order[j]).tet_count;
    Progress progress("verifying", "tets", my_tets, opt_.progress);
    slot_.resize(slots_);
    scratch_.resize(std::min<std::size_t>(slots_, std::size_t(std::max(1, omp_get_max_threads()))));
    std::vector<std::size_t> free_scratch(scratch_.size());
    std::iota(free_scratch.begin(), free_scratch.end(), std::size_t(0));
    std::vector<char> ready(slots_, 0), testing(slots_, 0);  // prepared; consumed, pairs not yet tested
    std::vector<std::size_t> to_test;                        // slots whose pairs wait
    std::size_t next_prepare = first, next_consume = first;
    bool consuming = false;
    std::exception_ptr error;
    std::mutex mutex;
    std::condition_variable changed;
    auto slot_of = [&](std::size_t j) { return (j - first) % slots_; };
#pragma omp parallel
    {
      std::unique_lock<std::mutex> lock(mutex);
      while (!error && (next_consume < last || !to_test.empty())) {
        std::exception_ptr failed;
        if (!consuming && next_consume < last && ready[slot_of(next_consume)]) {
          const std::size_t s = slot_of(next_consume);
          const std::uint64_t frame_min = mins[next_consume];
          consuming = true;
          lock.unlock();
          try {
            consume_frame(slot_[s]);
            release_points_outside(frame_min);
            progress.add(slot_[s].tets);
            check_interrupted();
          } catch (...) {
            failed = std::current_exception();
          }
          lock.lock();
          consuming = false, ready[s] = 0, ++next_consume;
          testing[s] = 1, to_test.push_back(s);
        } else if (!to_test.empty()) {
          const std::size_t s = to_test.back();
          to_test.pop_back();
          lock.unlock();
          try {
            check_pairs(slot_[s].pairs);
          } catch (...) {
            failed = std::current_exception();
          }
          lock.lock();
          testing[s] = 0;
        } else if (next_prepare < last && next_prepare < next_consume + slots_ && !testing[slot_of(next_prepare)] &&
                   !free_scratch.empty()) {
          const std::size_t j = next_prepare++, w = free_scratch.back();
          free_scratch.pop_back();
          lock.unlock();
          prepare_frame(order[j], later_min[j + 1], slot_[slot_of(j)], scratch_[w]);  // keeps its failure
          lock.lock();
          free_scratch.push_back(w);
          ready[slot_of(j)] = 1;
        } else {
          changed.wait(lock);
          continue;
        }
        if (failed && !error) error = failed;
        changed.notify_all();
      }
      changed.notify_all();
    }
    if (error) std::rethrow_exception(error);
    progress.finish();
    slot_ = {}, scratch_ = {};
    if (front_error_) std::rethrow_exception(front_error_);  // the pass did not meet it again
    seconds_tets_ = since(t1);

    // Every key this rank owns is final now (or goes to the spills): free the open
    // sets before the spills merge.
    const auto t2 = Clock::now();
    if (!sampled_) merge_edges(~0ull);
    live_e_.release(), merged_e_ = {}, spill_run_e_ = {};
    retire_facets(~0ull);
    live_.release(), merged_ = {}, spill_run_ = {};
    finish_facets();
    if (!sampled_) finish_edges();
    seconds_final_ = since(t2);
  });
  if (!sampled_) {
    // A boundary edge's key is its smaller label: to the rank that owns it.
    if (comm_.size() > 1) hand_over_hull_edges();
    together(comm_, [&] { finish_hull(); });
    hand_over_bits(hull_used_);
  }
  hand_over_bits(used_);
  finish();
  rep_.seconds = since(t0);
  spdlog::debug("verify: points {:.2f}s, tets {:.2f}s, final merges {:.2f}s", seconds_points_, seconds_tets_,
                seconds_final_);
}

// Hands back the points' pages more than behind_labels_ below the smallest label of the
// frame just consumed (plan_point_window()): the frames still to come start at or above
// it and their pairs reach about that far back; a slice at a time. After every frame,
// also the pages more than ahead_labels_ above it and those below the released floor:
// the few long tets of a frame fault in pages far from its reach, which would otherwise
// stay until the floor passes them (3 * 10^8 uniform points: 294 MB of mapped pages
// against a 51 MB window; 181 MB when released every 32nd frame). Cheap where nothing
// is resident (the kernel skips unmapped page tables). Reads outside are still right (the pages fault back in): this
// bounds the resident set, nothing else. Called by the consuming thread only.
template <class L>
void Engine<L>::release_points_outside(std::uint64_t frame_min) {
  if (released_below_ > 0) src_.release_points(0, released_below_);
  const std::uint64_t top = frame_min + ahead_labels_;
  if (top < n_) src_.release_points(top, n_ - top);
  const std::uint64_t floor = frame_min > behind_labels_ ? frame_min - behind_labels_ : 0;
  if (floor < released_below_ + release_slice_labels_) return;
  src_.release_points(released_below_, floor - released_below_);
  released_below_ = floor;
}

// One frame: storage, orientation and volume of every tet, then its facets and edges
// in steps of step_tets_ tets.
