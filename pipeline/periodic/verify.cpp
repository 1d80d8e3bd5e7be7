#include "pipeline/periodic/verify.hpp"

#include "core/predicates.hpp"
#include "io/tet_container.hpp"
#include "io/tet_periodic.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/files/external_sort.hpp"
#include "pipeline/periodic/pad.hpp"
#include "pipeline/periodic/tet_place.hpp"
#include "pipeline/periodic/tet_records.hpp"
#include "pipeline/verify/exact_sum.hpp"

#include <algorithm>
#include <cmath>
#include <tuple>

namespace tetstream::pipeline::periodic {

namespace {

struct EdgeRec {
  std::uint64_t a, b;
  std::uint64_t code;  // b's offset relative to a
  bool operator==(const EdgeRec&) const = default;
};
struct EdgeLess {
  bool operator()(const EdgeRec& x, const EdgeRec& y) const {
    return std::tie(x.a, x.b, x.code) < std::tie(y.a, y.b, y.code);
  }
};

void note(PeriodicVerifyReport& rep, const std::string& what) {
  if (rep.problem.empty()) rep.problem = what;
}

// The two facets of a pair: the opposite vertex of the second outside the first tet's
// circumsphere.
bool locally_delaunay(const io::TetReader& r, const io::PeriodicBox& box, const FacetRec& f, const FacetRec& g,
                      bool& placed) {
  const FacetRec& a = f.side == 0 ? f : g;  // a's sorted order is its outward orientation
  const FacetRec& b = f.side == 0 ? g : f;
  std::uint64_t label[5] = {a.v[0], a.v[1], a.v[2], a.opp, b.opp};
  int off[5][3] = {{0, 0, 0}};
  io::offset_of_code(a.off / 27, off[1]);
  io::offset_of_code(a.off % 27, off[2]);
  io::offset_of_code(a.opp_code, off[3]);
  io::offset_of_code(b.opp_code, off[4]);
  Placed p;
  placed = place(r, box, label, off, 5, p);
  if (!placed) return false;
  return core::insphere_sos(p.xyz[0], p.xyz[1], p.xyz[2], p.xyz[3], p.xyz[4], p.rank[0], p.rank[1], p.rank[2],
                            p.rank[3], p.rank[4]) < 0;
}

}  // namespace

PeriodicVerifyReport verify_periodic(const std::string& path, std::uint64_t memory_bytes, const std::string& dir) {
  PeriodicVerifyReport rep;
  const io::TetReader r(path, io::TetReader::Periodic::kAccept);
  if (!r.periodic()) throw InputError(path + ": not a periodic container (no PBOX section)");
  const io::PeriodicBox box = io::parse_periodic_box(r.section(io::kTagPeriodicBox), path);
  const io::PeriodicOffsetsReader offsets(r);
  rep.points = r.point_count();
  const std::size_t share = std::max<std::uint64_t>(memory_bytes / 3, std::uint64_t(32) << 20);
  ExternalSorter<FacetRec, FacetLess> facets(sort_options(share, dir, "periodic-facets"));
  ExternalSorter<EdgeRec, EdgeLess> edges(sort_options(share, dir, "periodic-edges"));
  std::vector<std::uint8_t> used(r.point_count(), 0);
  verify_engine::ExactSum volume, bound;
  for_each_stored_tet(r, offsets, [&](const KeptTet& t, std::uint64_t k, std::size_t i) {
    int off[4][3];
    stored_offsets(t, off);
    Placed p;
    FacetRec fr[4];
    if (!place(r, box, t.v, off, 4, p) || !facets_of(t, fr)) {
      ++rep.inexact;
      note(rep, "frame " + std::to_string(k) + ": tet " + std::to_string(i) + " spans more than a period");
      return;
    }
    if (core::orient3d(p.xyz[0], p.xyz[1], p.xyz[2], p.xyz[3]) <= 0) {
      ++rep.bad_orientation;
      note(rep, "frame " + std::to_string(k) + ": tet " + std::to_string(i) + " is not positively oriented");
    }
    const auto d = verify_engine::det3_bounded<long double>(p.xyz[0], p.xyz[1], p.xyz[2], p.xyz[3]);
    volume.add(d.value / 6);
    bound.add(d.error / 6 * (1 + 0x1p-50L));
    facets.push(std::span<const FacetRec>(fr, 4));
    for (int a = 0; a < 4; ++a) {
      used[t.v[a]] = 1;
      for (int b = a + 1; b < 4; ++b) {
        const int lo = t.v[a] < t.v[b] ? a : b, hi = lo == a ? b : a;
        int o[3];
        for (int c = 0; c < 3; ++c) o[c] = off[hi][c] - off[lo][c];
        edges.push(EdgeRec{t.v[lo], t.v[hi], std::uint64_t(io::offset_code(o))});
      }
    }
    ++rep.tets;
  });
  // Facets: pairs, from opposite sides, locally Delaunay.
  std::vector<FacetRec> group;
  const auto close = [&] {
    if (group.empty()) return;
    ++rep.facets;
    if (group.size() != 2 || group[0].side == group[1].side) {
      rep.unpaired += group.size();
      note(rep, "facet (" + std::to_string(group[0].v[0]) + ", " + std::to_string(group[0].v[1]) + ", " +
                    std::to_string(group[0].v[2]) + ") is shared by " + std::to_string(group.size()) + " tets");
    } else {
      bool placed = true;
      if (!locally_delaunay(r, box, group[0], group[1], placed)) {
        ++(placed ? rep.not_delaunay : rep.inexact);
        note(rep, "facet (" + std::to_string(group[0].v[0]) + ", " + std::to_string(group[0].v[1]) + ", " +
                      std::to_string(group[0].v[2]) + ") is not locally Delaunay");
      }
    }
    group.clear();
  };
  facets.merge([&](std::span<const FacetRec> batch) {
    for (const FacetRec& f : batch) {
      if (!group.empty() && facet_key(f) != facet_key(group[0])) close();
      group.push_back(f);
    }
  });
  close();
  EdgeRec last{};
  bool any = false;
  edges.merge([&](std::span<const EdgeRec> batch) {
    for (const EdgeRec& e : batch) {
      if (!any || !(e == last)) ++rep.edges;
      last = e;
      any = true;
    }
  });
  rep.vertices = std::uint64_t(std::count(used.begin(), used.end(), 1));
  rep.euler = std::int64_t(rep.vertices) - std::int64_t(rep.edges) + std::int64_t(rep.facets) - std::int64_t(rep.tets);
  if (rep.vertices != rep.points)
    note(rep,
         std::to_string(rep.points - rep.vertices) + " points are no tet's vertex (every point of a torus is one)");
  if (rep.euler != 0) note(rep, "Euler characteristic " + std::to_string(rep.euler) + ", not 0");
  rep.volume = volume.value();
  rep.volume_bound = bound.value();
  rep.expected = (long double)box.period[0] * box.period[1] * box.period[2];
  const long double gap = std::fabs(rep.volume - rep.expected);
  // The degree of the covering is an integer: volume = degree * box exactly, so a
  // difference within the bounds, and bounds below half the box, prove degree 1.
  if (!(gap <= rep.volume_bound + rep.expected * 0x1p-60L) || !(rep.volume_bound < rep.expected / 2))
    note(rep, "volume " + std::to_string(double(rep.volume)) + " differs from the box's " +
                  std::to_string(double(rep.expected)));
  rep.ok = rep.problem.empty();
  return rep;
}

}  // namespace tetstream::pipeline::periodic
