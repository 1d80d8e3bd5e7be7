// The boundary surface (closed, locally convex), Euler, volume, and the report (members of Engine,
// pipeline/verify/engine.hpp; compiled in engine.cpp). Included once, by engine.cpp, inside namespace
// tetstream::pipeline::verify_engine.

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
      const int s1 = infinite_conflict_sos(u, v, w1, w2);
      const int s2 = infinite_conflict_sos(v, u, w2, w1);
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

// The report. Each rank counts the vertices of its own labels (its bitmaps hold the
// whole job's bits there, hand_over_bits) and lists its missing points; rank 0 adds
// every rank's totals and runs the checks of the whole (Euler, hull topology, volume).
template <class L>
void Engine<L>::finish() {
  VerifyReport& r = rep_;
  const std::uint64_t lo = std::min(lower_, n_), hi = std::min(upper_, n_);
  vertices_ = used_.count(lo, hi);
  if (!sampled_) hull_vertices_ = hull_used_.count(lo, hi);
  // Coverage: every label a vertex.
  if (vertices_ < hi - lo) {
    for (std::uint64_t l = lo; l < hi; ++l)
      if (!used_.get(l))
        log_.add(Violation::kMissingPoint, l, [&] {
          const PointCoords::Point p = P(l);
          return "point " + std::to_string(l) + " (" + std::to_string(p[0]) + ", " + std::to_string(p[1]) + ", " +
                 std::to_string(p[2]) + ") is in no tet";
        });
  }
  const std::vector<std::string> parts = comm_.gather(partial_totals(), 0);
  if (comm_.rank() == 0) {
    merge_totals(parts);
    totals_into_report();
  }
  // Every rank learns the verdict (the counts): the job exits with one code.
  std::string counts(reinterpret_cast<const char*>(r.counts.data()), sizeof r.counts);
  counts = comm_.broadcast(counts, 0);
  std::memcpy(r.counts.data(), counts.data(), sizeof r.counts);
}

// Rank 0: the job's totals into the report, with the checks of the whole.
template <class L>
void Engine<L>::totals_into_report() {
  VerifyReport& r = rep_;
  r.sampled = sampled_;
  r.sample = opt_.sample;
  r.points = n_;
  r.tets = src_.tet_count();
  r.vertices = vertices_;
  r.interior_facets = interior_;
  r.boundary_facets = boundary_;
  r.facets = interior_ + boundary_ + bad_facets_;
  r.orient_tests = orient_tests_.load();
  r.insphere_tests = insphere_tests_.load();
  r.hull_tests = hull_tests_.load();
  r.tets_checked = tets_checked_;
  r.facets_checked = facets_checked_;
  if (!sampled_) {
    r.edges = edges_;
    r.hull_vertices = hull_vertices_;
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
    const long double tets6 = tet_volume6_.value(), hull6 = hull_volume6_.value();
    r.tet_volume = double(tets6 / 6);
    r.hull_volume = double(hull6 / 6);
    const long double scale = std::max(std::fabs(hull6), std::numeric_limits<long double>::min());
    r.volume_rel_error = double(std::fabs(tets6 - hull6) / scale);
    // The verdict: the exact difference of the two sums against the sum of their
    // terms' rounding bounds (each sum exact, so the bounds add up), plus the relative
    // tolerance. A correct output always passes, however flat; the other checks
    // (coverage, pairing, the closed convex boundary, Euler) catch the rest.
    ExactSum diff = tet_volume6_;
    diff.subtract(hull_volume6_);
    ExactSum slack = tet_error6_;
    slack.add(hull_error6_);
    // value() rounds towards zero: the slack is rounded up by a relative 2^-60.
    const long double allowed = slack.value() * (1 + 0x1p-60L) + (long double)opt_.volume_tolerance * std::fabs(hull6);
    const bool volume_ok = std::fabs(diff.value()) <= allowed;
    if (!volume_ok)
      log_.add(Violation::kVolume, 0, [&] {
        std::ostringstream s;
        s.precision(17);
        s << "tets fill " << r.tet_volume << ", the boundary encloses " << r.hull_volume << ": they differ by "
          << double(std::fabs(diff.value()) / 6) << " (relative " << r.volume_rel_error
          << "), more than the rounding bound " << double(slack.value() / 6) << " plus the relative tolerance "
          << opt_.volume_tolerance;
        return s.str();
      });
  }
  log_.into(r);
}
