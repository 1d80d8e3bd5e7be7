#include "io/point_cosmic.hpp"

#include "io/point_rng.hpp"

#include <algorithm>
#include <array>
#include <cmath>

namespace tetstream::io {

namespace {

constexpr std::uint64_t kPurposeWeb = 0x636f736dULL;  // "cosm"
constexpr int kNodes = 64, kLinks = 3, kHaloes = 4096, kVoids = 40;
constexpr double kFilamentWidth = 0.004;  // the Gaussian cross-section's deviation
constexpr double kHaloScatter = 0.002;    // of a halo's centre about its filament
// Halo masses m in [1, 1000] with dn/dm ~ m^-1.9 (a mass function's slope below the
// knee); radius kHaloRadius m^(1/3), so the largest is ten times the smallest.
constexpr double kMassSlope = 1.9, kMassRange = 1000, kHaloRadius = 0.004;

double wrap(double x) {
  x -= std::floor(x);
  return x < 1.0 ? x : 0.0;  // -tiny wraps to 1 - tiny, which may round to 1
}

// The periodic difference b - a, in [-1/2, 1/2).
double periodic_delta(double a, double b) {
  const double d = b - a;
  return d - std::floor(d + 0.5);
}

double periodic_distance2(const double* a, const double* b) {
  double s = 0;
  for (int k = 0; k < 3; ++k) {
    const double d = periodic_delta(a[k], b[k]);
    s += d * d;
  }
  return s;
}

}  // namespace

bool CosmicWeb::in_void(const double* p) const {
  return std::any_of(voids_.begin(), voids_.end(),
                     [&](const Void& v) { return periodic_distance2(p, v.centre) < v.radius * v.radius; });
}

CosmicWeb::CosmicWeb(std::uint64_t seed) {
  rng::PointRng r(rng::key_for(seed, kPurposeWeb), 0);
  // The web's nodes, each joined to its kLinks nearest (periodically): the filaments.
  std::vector<std::array<double, 3>> nodes(kNodes);
  for (auto& n : nodes)
    for (double& x : n) x = r.uniform();
  double total = 0;
  for (int i = 0; i < kNodes; ++i) {
    std::vector<std::pair<double, int>> by_distance;
    for (int j = 0; j < kNodes; ++j)
      if (j != i) by_distance.push_back({periodic_distance2(nodes[i].data(), nodes[j].data()), j});
    std::partial_sort(by_distance.begin(), by_distance.begin() + kLinks, by_distance.end());
    for (int l = 0; l < kLinks; ++l) {
      const int j = by_distance[std::size_t(l)].second;
      if (j < i &&
          std::any_of(by_distance.begin(), by_distance.begin() + kLinks, [&](const auto& e) { return e.second == j; }))
        continue;  // the pair is linked both ways: once
      Filament f;
      for (int k = 0; k < 3; ++k) {
        f.from[k] = nodes[i][std::size_t(k)];
        f.to[k] = f.from[k] + periodic_delta(f.from[k], nodes[std::size_t(j)][std::size_t(k)]);
      }
      filaments_.push_back(f);
      total += std::sqrt(by_distance[std::size_t(l)].first);
      filament_cdf_.push_back(total);
    }
  }
  for (double& c : filament_cdf_) c /= total;
  filament_cdf_.back() = 1;
  // The voids: spheres clear of every node.
  while (voids_.size() < std::size_t(kVoids)) {
    Void v;
    for (double& x : v.centre) x = r.uniform();
    v.radius = 0.04 + 0.08 * r.uniform();
    if (std::none_of(nodes.begin(), nodes.end(),
                     [&](const auto& n) { return periodic_distance2(n.data(), v.centre) < v.radius * v.radius; }))
      voids_.push_back(v);
  }
  // The haloes: 60% on a filament, the others at random, none in a void.
  double mass = 0;
  while (haloes_.size() < std::size_t(kHaloes)) {
    Halo h;
    if (r.uniform() < 0.6) {
      const Filament& f = filaments_[std::size_t(r.uniform() * double(filaments_.size()))];
      const double t = r.uniform();
      for (int k = 0; k < 3; ++k) h.centre[k] = wrap(f.from[k] + t * (f.to[k] - f.from[k]) + kHaloScatter * r.normal());
    } else {
      for (double& x : h.centre) x = r.uniform();
    }
    // m = (1 - u (1 - M^-(s-1)))^(-1/(s-1)): the power law on [1, M].
    const double a = kMassSlope - 1;
    const double m = std::pow(1 - r.uniform() * (1 - std::pow(kMassRange, -a)), -1 / a);
    h.radius = kHaloRadius * std::cbrt(m);
    if (in_void(h.centre)) continue;
    haloes_.push_back(h);
    mass += m;
    halo_cdf_.push_back(mass);
  }
  for (double& c : halo_cdf_) c /= mass;
  halo_cdf_.back() = 1;
}

void CosmicWeb::point(rng::PointRng& rng, double* p) const {
  const double kind = rng.uniform();
  if (kind < kHaloFraction) {
    // A halo drawn by mass, a point at radius R u^2 (density ~ r^-2.5 inside, a cusp).
    const auto it = std::upper_bound(halo_cdf_.begin(), halo_cdf_.end(), rng.uniform());
    const Halo& h = haloes_[std::min<std::size_t>(std::size_t(it - halo_cdf_.begin()), haloes_.size() - 1)];
    const double u = rng.uniform(), r = h.radius * u * u;
    double d[3];
    rng.direction(d);
    for (int k = 0; k < 3; ++k) p[k] = wrap(h.centre[k] + r * d[k]);
    return;
  }
  // A filament's point or the field's, thinned to kVoidDensity inside a void.
  for (;;) {
    if (kind < kHaloFraction + kFilamentFraction) {
      const auto it = std::upper_bound(filament_cdf_.begin(), filament_cdf_.end(), rng.uniform());
      const Filament& f =
          filaments_[std::min<std::size_t>(std::size_t(it - filament_cdf_.begin()), filaments_.size() - 1)];
      const double t = rng.uniform();
      for (int k = 0; k < 3; ++k) p[k] = wrap(f.from[k] + t * (f.to[k] - f.from[k]) + kFilamentWidth * rng.normal());
    } else {
      for (int k = 0; k < 3; ++k) p[k] = rng.uniform();
    }
    if (!in_void(p) || rng.uniform() < kVoidDensity) return;
  }
}

}  // namespace tetstream::io
