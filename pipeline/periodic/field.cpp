#include "pipeline/periodic/field.hpp"

#include "core/error.hpp"
#include "io/npy.hpp"
#include "io/tet_container.hpp"
#include "io/tet_periodic.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/field/geometry.hpp"
#include "pipeline/periodic/tet_place.hpp"
#include "pipeline/periodic/tet_records.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace tetstream::pipeline::periodic {

namespace {

struct Tets {
  const io::TetReader& reader;
  io::PeriodicBox box;
  io::PeriodicOffsetsReader offsets;
};

// Calls visit(p) with each tet's four vertices at exact coordinates (placed), in the
// container's order, and its labels.
template <class Visit>
void for_each_tet(const Tets& t, Visit&& visit) {
  for_each_stored_tet(t.reader, t.offsets, [&](const KeptTet& k, std::uint64_t f, std::size_t i) {
    int off[4][3];
    stored_offsets(k, off);
    Placed p;
    if (!place(t.reader, t.box, k.v, off, 4, p))
      throw InputError(t.reader.path() + ": frame " + std::to_string(f) + ": tet " + std::to_string(i) +
                       " spans more than a period (tetstream verify says more)");
    visit(k.v, p);
  });
}

// Barycentric coordinates of g in the tet p (floating point, from sub-volumes).
bool inside_with_slack(const double* const p[4], const double* g) {
  const double* q[4];
  const double total = tet_volume(p);
  for (int i = 0; i < 4; ++i) {
    std::copy(p, p + 4, q);
    q[i] = g;
    if (tet_volume(q) < -1e-9 * total) return false;
  }
  return true;
}

// The DTFE field on the grid's cell centres: each centre is found in a tet, the tet
// moved by whole periods onto it (placed vertices lie in [-L, L)).
void sample_grid(const Tets& t, const std::vector<double>& rho_by_label, const PeriodicFieldOptions& o,
                 std::vector<double>& grid) {
  const auto& L = t.box.period;
  const auto& n = o.grid;
  grid.assign(n[0] * n[1] * n[2], std::numeric_limits<double>::quiet_NaN());
  for_each_tet(t, [&](const std::uint64_t* v, const Placed& p) {
    const double f[4] = {rho_by_label[v[0]], rho_by_label[v[1]], rho_by_label[v[2]], rho_by_label[v[3]]};
    for (int s = 0; s < 8; ++s) {
      double q[4][3];
      const double* qp[4];
      for (int i = 0; i < 4; ++i) {
        for (int k = 0; k < 3; ++k) q[i][k] = p.xyz[i][k] + ((s >> k & 1) ? L[k] : 0.0);
        qp[i] = q[i];
      }
      std::uint64_t lo[3], hi[3];
      bool empty = false;
      for (int k = 0; k < 3 && !empty; ++k) {
        double a = q[0][k], b = q[0][k];
        for (int i = 1; i < 4; ++i) a = std::min(a, q[i][k]), b = std::max(b, q[i][k]);
        // cells whose centre (c + 0.5) L / n lies in [a, b], clipped to the box
        const double ca = std::ceil(a / L[k] * double(n[k]) - 0.5 - 1e-9),
                     cb = std::floor(b / L[k] * double(n[k]) - 0.5 + 1e-9);
        const double c0 = std::max(ca, 0.0), c1 = std::min(cb, double(n[k]) - 1);
        empty = c1 < c0;
        lo[k] = std::uint64_t(std::max(c0, 0.0));
        hi[k] = empty ? 0 : std::uint64_t(c1);
      }
      if (empty) continue;
      for (std::uint64_t i = lo[0]; i <= hi[0]; ++i)
        for (std::uint64_t j = lo[1]; j <= hi[1]; ++j)
          for (std::uint64_t l = lo[2]; l <= hi[2]; ++l) {
            double& cell = grid[(i * n[1] + j) * n[2] + l];
            if (!std::isnan(cell)) continue;
            const double g[3] = {(double(i) + 0.5) * L[0] / double(n[0]), (double(j) + 0.5) * L[1] / double(n[1]),
                                 (double(l) + 0.5) * L[2] / double(n[2])};
            if (inside_with_slack(qp, g)) cell = tet_interpolate(qp, f, g);
          }
    }
  });
}

// Writes values indexed by label in the input's order (ascending original index).
std::string write_points(const std::string& path, const std::vector<double>& by_label,
                         const std::vector<std::uint64_t>& order, bool float32) {
  io::NpyArrayWriter w(path, float32 ? "<f4" : "<f8", {order.size()});
  if (float32) {
    std::vector<float> v(order.size());
    for (std::size_t i = 0; i < order.size(); ++i) v[i] = float(by_label[order[i]]);
    w.write(v.data(), v.size() * 4);
  } else {
    std::vector<double> v(order.size());
    for (std::size_t i = 0; i < order.size(); ++i) v[i] = by_label[order[i]];
    w.write(v.data(), v.size() * 8);
  }
  w.commit();
  return path;
}

}  // namespace

PeriodicFieldResult periodic_field(const std::string& container, const PeriodicFieldOptions& o) {
  const io::TetReader r(container, io::TetReader::Periodic::kAccept);
  if (!r.periodic()) throw InputError(container + ": not a periodic container (no PBOX section)");
  r.verify_points();
  const Tets t{r, io::parse_periodic_box(r.section(io::kTagPeriodicBox), container), io::PeriodicOffsetsReader(r)};
  PeriodicFieldResult res;
  const std::uint64_t n = r.point_count();
  res.points = n;
  std::vector<double> star(n, 0.0), voronoi(o.voronoi ? n : 0, 0.0);
  for_each_tet(t, [&](const std::uint64_t* v, const Placed& p) {
    const double* q[4] = {p.xyz[0], p.xyz[1], p.xyz[2], p.xyz[3]};
    const TetContribution c = tet_contribution(q, o.voronoi);
    for (int i = 0; i < 4; ++i) {
      star[v[i]] += c.volume;
      if (o.voronoi) voronoi[v[i]] += c.voronoi[i];
    }
    ++res.tets;
  });
  std::vector<double> rho(n);
  for (std::uint64_t i = 0; i < n; ++i) {
    rho[i] = 4.0 / star[i];
    res.nan_points += !std::isfinite(rho[i]) || !(star[i] > 0);
    res.mass_check += rho[i] * star[i] / 4;
    res.star_sum += star[i];
    if (o.voronoi) res.voronoi_sum += voronoi[i];
  }
  // The input's order: labels sorted by original index.
  std::vector<std::uint64_t> ids(n), order(n);
  r.read_points(0, n, nullptr, ids.data());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](std::uint64_t a, std::uint64_t b) { return ids[a] < ids[b]; });
  if (o.density) res.files.push_back(write_points(o.prefix + ".density.npy", rho, order, o.float32));
  if (o.voronoi) res.files.push_back(write_points(o.prefix + ".voronoi.npy", voronoi, order, o.float32));
  if (o.grid[0] != 0) {
    std::vector<double> grid;
    sample_grid(t, rho, o, grid);
    res.nan_cells = std::uint64_t(std::count_if(grid.begin(), grid.end(), [](double x) { return std::isnan(x); }));
    io::NpyArrayWriter w(o.prefix + ".grid.npy", o.float32 ? "<f4" : "<f8", {o.grid[0], o.grid[1], o.grid[2]});
    if (o.float32) {
      std::vector<float> g(grid.begin(), grid.end());
      w.write(g.data(), g.size() * 4);
    } else {
      w.write(grid.data(), grid.size() * 8);
    }
    w.commit();
    res.files.push_back(o.prefix + ".grid.npy");
  }
  return res;
}

}  // namespace tetstream::pipeline::periodic
