#include "io/point_zoo.hpp"

#include "io/point_rng.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace tetstream::io {

namespace {

using rng::key_for;
using rng::PointRng;

// Distinct keys for the independent uses of one seed (the other generators use others).
constexpr std::uint64_t kPurposeTilePoint = 0x74706e74ULL;  // "tpnt"
constexpr std::uint64_t kPurposeTilePulse = 0x7470756cULL;  // "tpul"
constexpr std::uint64_t kPurposeTileShape = 0x74736870ULL;  // "tshp"
constexpr std::uint64_t kPurposeTileBldg = 0x74626c64ULL;   // "tbld"
constexpr std::uint64_t kPurposeTileTree = 0x74747265ULL;   // "ttre"
constexpr std::uint64_t kPurposeIndoor = 0x696e646fULL;     // "indo"

constexpr double kTau = 2 * std::numbers::pi;
constexpr double kBuildingCell = 40, kTreeCell = 8;
constexpr double kStripOverlap = 0.3;  // of a strip's width, shared with its neighbour
constexpr int kReturnsPerPulse = 3;    // canopy pulses: first, intermediate, last

double centimetres(double v) { return std::round(v * 100) / 100; }
double millimetres(double v) { return std::round(v * 1000) / 1000; }

std::uint64_t cell_id(std::int64_t cx, std::int64_t cy) { return std::uint64_t(cx) * 1000003u + std::uint64_t(cy); }

}  // namespace

LidarTile::LidarTile(Preset preset, std::uint64_t seed, std::uint64_t n) {
  switch (preset) {
    case Preset::kHills:
      break;  // relief set below, from the side
    case Preset::kRoofs:
      f_.building_share = 0.35;
      break;
    case Preset::kCanopy:
      f_.tree_share = 0.85;
      break;
    case Preset::kWater:
      f_.building_share = 0.2;
      f_.lakes = true;
      break;
    case Preset::kStrips:
      f_.strips = f_.scan_lines = true;
      break;
    case Preset::kScanLines:
      f_.scan_lines = true;
      break;
    case Preset::kSurvey:
      f_.building_share = 0.25;
      f_.tree_share = 0.15;
      f_.lakes = f_.strips = f_.scan_lines = true;
      break;
  }
  // The side that gives one strip's coverage the scanner's density, overlaps counted.
  const double density = 1 / (kPulseSpacing * kLineSpacing);
  const double side0 = std::sqrt(double(n) / density);
  const int strips = f_.strips ? std::max(2, int(std::lround(side0 / 300))) : 1;
  const double coverage = strips / (1 + (strips - 1) * (1 - kStripOverlap));
  side_ = std::max(100.0, std::ceil(std::sqrt(double(n) / (density * coverage))));
  strip_width_ = side_ / (1 + (strips - 1) * (1 - kStripOverlap));
  if (preset == Preset::kHills) {
    // Steep hills as wide as the tile: the hull spans the valleys between hilltops.
    f_.hill_amplitude = 0.12 * side_;
    f_.hill_wavelength = 0.5 * side_;
  } else if (preset == Preset::kSurvey) {
    f_.hill_amplitude = 0.05 * side_;
    f_.hill_wavelength = 0.6 * side_;
  }

  key_point_ = key_for(seed, kPurposeTilePoint);
  key_pulse_ = key_for(seed, kPurposeTilePulse);
  key_buildings_ = key_for(seed, kPurposeTileBldg);
  key_trees_ = key_for(seed, kPurposeTileTree);
  PointRng shape(key_for(seed, kPurposeTileShape), 0);
  for (double& ph : phase_) ph = kTau * shape.uniform();
  for (int s = 0; s < strips; ++s) {
    strip_x0_.push_back(s * strip_width_ * (1 - kStripOverlap));
    strip_line_phase_.push_back(shape.uniform() * kLineSpacing);
  }
  if (f_.lakes) {
    const int count = 1 + int(side_ / 500);
    for (int k = 0; k < count; ++k) {
      Lake l;
      l.centre[0] = side_ * (0.1 + 0.8 * shape.uniform());
      l.centre[1] = side_ * (0.1 + 0.8 * shape.uniform());
      l.radii[0] = side_ * (0.06 + 0.08 * shape.uniform());
      l.radii[1] = side_ * (0.06 + 0.08 * shape.uniform());
      lakes_.push_back(l);
    }
  }
}

double LidarTile::ground(double x, double y) const {
  const double a = f_.hill_amplitude, w = f_.hill_wavelength;
  return a * (0.75 * std::sin(kTau * x / w + phase_[0]) * std::cos(kTau * y / (1.3 * w) + phase_[1]) +
              0.25 * std::sin(kTau * (x + y) / (0.33 * w) + phase_[2])) +
         0.8 * std::sin(kTau * x / 57 + phase_[3]) * std::sin(kTau * y / 43);
}

bool LidarTile::building(std::int64_t cx, std::int64_t cy, Building* b, bool heights) const {
  if (f_.building_share <= 0 || cx < 0 || cy < 0) return false;
  if (double(cx + 1) * kBuildingCell > side_ || double(cy + 1) * kBuildingCell > side_) return false;
  PointRng r(key_buildings_, cell_id(cx, cy));
  if (!(r.uniform() < f_.building_share)) return false;
  double centre[2];
  for (int c = 0; c < 2; ++c) {
    const double w = 10 + 18 * r.uniform();
    const double play = (kBuildingCell - w) / 2 - 3;  // 3 m from the cell's edge at least
    centre[c] = (double(c == 0 ? cx : cy) + 0.5) * kBuildingCell + play * r.symmetric();
    b->lo[c] = centre[c] - w / 2, b->hi[c] = centre[c] + w / 2;
  }
  for (const Lake& l : lakes_) {  // no houses in the lakes
    const double dx = (centre[0] - l.centre[0]) / (l.radii[0] + 25), dy = (centre[1] - l.centre[1]) / (l.radii[1] + 25);
    if (dx * dx + dy * dy < 1) return false;
  }
  b->gable = r.uniform() < 0.5;
  b->pitch = std::tan((25 + 15 * r.uniform()) * std::numbers::pi / 180);
  const double rise = b->gable ? 3 + 12 * r.uniform() : 4 + 16 * r.uniform();
  b->eave = b->shadow = 0;
  if (!heights) return true;  // the ground's five samples are most of the cost
  double base = ground(centre[0], centre[1]);
  for (double x : {b->lo[0], b->hi[0]})
    for (double y : {b->lo[1], b->hi[1]}) base = std::max(base, ground(x, y));
  b->eave = base + rise;
  const double ridge = b->gable ? b->pitch * std::min(b->hi[0] - b->lo[0], b->hi[1] - b->lo[1]) / 2 : 0;
  b->shadow = 0.35 * (b->eave + ridge - ground(centre[0], centre[1]));
  return true;
}

bool LidarTile::building_at(double x, double y, Building* b) const {
  Building tmp;
  Building* out = b ? b : &tmp;
  const auto cx = std::int64_t(std::floor(x / kBuildingCell)), cy = std::int64_t(std::floor(y / kBuildingCell));
  if (!building(cx, cy, out, false)) return false;
  if (!(x >= out->lo[0] && x <= out->hi[0] && y >= out->lo[1] && y <= out->hi[1])) return false;
  if (b) building(cx, cy, out, true);
  return true;
}

double LidarTile::roof(const Building& b, double x, double y) const {
  if (!b.gable) return b.eave;
  const double wx = b.hi[0] - b.lo[0], wy = b.hi[1] - b.lo[1];
  // The ridge runs along the longer side; the roof falls to the eaves across it.
  const double across =
      wx >= wy ? wy / 2 - std::fabs(y - (b.lo[1] + b.hi[1]) / 2) : wx / 2 - std::fabs(x - (b.lo[0] + b.hi[0]) / 2);
  return b.eave + b.pitch * std::max(0.0, across);
}

bool LidarTile::tree_in_cell(std::int64_t cx, std::int64_t cy, Tree* t, bool heights) const {
  if (f_.tree_share <= 0 || cx < 0 || cy < 0) return false;
  PointRng r(key_trees_, cell_id(cx, cy));
  if (!(r.uniform() < f_.tree_share)) return false;
  t->centre[0] = (double(cx) + r.uniform()) * kTreeCell;
  t->centre[1] = (double(cy) + r.uniform()) * kTreeCell;
  t->radius = 2 + 2.5 * r.uniform();
  const double rise = 6 + 16 * r.uniform(), depth = 0.4 + 0.3 * r.uniform();
  // Not through a roof nor in a lake: a crown whose disc reaches either is not grown.
  for (int k = 0; k < 5; ++k) {
    const double x = t->centre[0] + (k == 1 ? t->radius : k == 2 ? -t->radius : 0);
    const double y = t->centre[1] + (k == 3 ? t->radius : k == 4 ? -t->radius : 0);
    if (building_at(x, y, nullptr)) return false;
    for (const Lake& l : lakes_) {
      const double dx = (x - l.centre[0]) / l.radii[0], dy = (y - l.centre[1]) / l.radii[1];
      if (dx * dx + dy * dy < 1) return false;
    }
  }
  t->top = t->base = 0;
  if (!heights) return true;
  const double g = ground(t->centre[0], t->centre[1]);
  t->top = g + rise;
  t->base = t->top - depth * rise;
  return true;
}

double LidarTile::crown_top(const Tree& t, double x, double y) {
  const double dx = x - t.centre[0], dy = y - t.centre[1];
  const double d2 = (dx * dx + dy * dy) / (t.radius * t.radius);
  const double half = (t.top - t.base) / 2;
  return t.base + half + half * std::sqrt(std::max(0.0, 1 - d2));
}

bool LidarTile::tree_at(double x, double y, Tree* t) const {
  if (f_.tree_share <= 0) return false;
  const auto cx = std::int64_t(std::floor(x / kTreeCell)), cy = std::int64_t(std::floor(y / kTreeCell));
  bool found = false;
  double best = 0;
  for (std::int64_t i = cx - 1; i <= cx + 1; ++i) {
    for (std::int64_t j = cy - 1; j <= cy + 1; ++j) {
      Tree c;
      if (!tree_in_cell(i, j, &c, false)) continue;
      const double dx = x - c.centre[0], dy = y - c.centre[1];
      if (dx * dx + dy * dy > c.radius * c.radius) continue;
      tree_in_cell(i, j, &c, true);
      const double top = crown_top(c, x, y);
      if (!found || top > best) found = true, best = top, *t = c;
    }
  }
  return found;
}

bool LidarTile::in_hole(double x, double y) const {
  if (!f_.lakes) return false;
  for (const Lake& l : lakes_) {
    const double dx = (x - l.centre[0]) / l.radii[0], dy = (y - l.centre[1]) / l.radii[1];
    if (dx * dx + dy * dy <= 1) return true;
  }
  // The scan shadow: the ground beyond a building's +x wall that the slanted pulses do
  // not reach. It may cross into the next cell.
  const auto cx = std::int64_t(std::floor(x / kBuildingCell)), cy = std::int64_t(std::floor(y / kBuildingCell));
  for (std::int64_t i : {cx, cx - 1}) {
    Building b;
    if (!building(i, cy, &b, false) || !(x > b.hi[0] && y >= b.lo[1] && y <= b.hi[1])) continue;
    building(i, cy, &b, true);
    if (x <= b.hi[0] + b.shadow) return true;
  }
  return false;
}

void LidarTile::draw_xy(PointRng& r, double* xy) const {
  // A pulse that meets water or a shadow returns nothing: draw again (a draw lands in a
  // hole with probability well under one half, so 1000 misses do not happen).
  for (int attempt = 0; attempt < 1000; ++attempt) {
    const int strips = int(strip_x0_.size());
    const int s = std::min(strips - 1, int(r.uniform() * strips));
    double x = strip_x0_[std::size_t(s)] + strip_width_ * r.uniform(), y;
    if (f_.scan_lines) {
      const double phase = strip_line_phase_[std::size_t(s)];
      const auto lines = std::int64_t(std::floor((side_ - phase) / kLineSpacing)) + 1;
      const auto k = std::min(lines - 1, std::int64_t(r.uniform() * double(lines)));
      y = phase + double(k) * kLineSpacing + 0.02 * r.symmetric();  // a line wobbles by centimetres
    } else {
      y = side_ * r.uniform();
    }
    x = std::clamp(x, 0.0, side_), y = std::clamp(y, 0.0, side_);
    xy[0] = x, xy[1] = y;
    if (!in_hole(x, y)) return;
  }
}

void LidarTile::point(std::uint64_t i, double* p) const {
  double x = 0, y = 0, z = 0;
  bool done = false;
  if (f_.tree_share > 0) {
    // Points come in groups of three indices, one pulse: where it meets a crown, they
    // are its first, an intermediate and its last return, along the slanted pulse.
    PointRng pulse(key_pulse_, i / kReturnsPerPulse);
    double xy[2];
    draw_xy(pulse, xy);
    Tree t;
    if (!building_at(xy[0], xy[1], nullptr) && tree_at(xy[0], xy[1], &t)) {
      const double slant = 0.35 * pulse.symmetric();  // tan of the scan angle, across the flight
      const double first = crown_top(t, xy[0], xy[1]) - 0.5 * pulse.uniform() * pulse.uniform();
      const double inner = t.base + (first - t.base) * pulse.uniform();
      const auto r = int(i % kReturnsPerPulse);
      z = r == 0 ? first : inner;
      if (r == 2) {  // the last return: the ground under the crown, where the pulse meets it
        const double gx = std::clamp(xy[0] + slant * (first - ground(xy[0], xy[1])), 0.0, side_);
        if (!in_hole(gx, xy[1]) && !building_at(gx, xy[1], nullptr)) {
          xy[0] = gx;
          z = ground(gx, xy[1]);
        }
      } else {
        const double sx = std::clamp(xy[0] + slant * (first - z), 0.0, side_);
        if (!in_hole(sx, xy[1]) && !building_at(sx, xy[1], nullptr)) xy[0] = sx;
      }
      x = xy[0], y = xy[1], done = true;
    }
  }
  if (!done) {
    PointRng r(key_point_, i);
    double xy[2];
    draw_xy(r, xy);
    x = xy[0], y = xy[1];
    Building b;
    Tree t;
    if (building_at(x, y, &b))
      z = roof(b, x, y);  // no wall returns: roofs and ground only
    else if (tree_at(x, y, &t))
      z = crown_top(t, x, y) - 0.5 * r.uniform() * r.uniform();
    else
      z = ground(x, y) + 0.03 * r.symmetric();
  }
  p[0] = centimetres(x) + kOffsetX, p[1] = centimetres(y) + kOffsetY, p[2] = centimetres(z) + kOffsetZ;
}

IndoorScan::IndoorScan(std::uint64_t seed) {
  key_point_ = key_for(seed, kPurposeIndoor);
  PointRng r(key_for(seed, kPurposeIndoor ^ 0x726f6f6dULL), 0);
  // Three rooms by two, walls 0.2 m thick on shared centre lines, one ceiling height.
  constexpr int kCols = 3, kRows = 2;
  constexpr double kWall = 0.2;
  double xs[kCols + 1] = {0}, ys[kRows + 1] = {0};
  for (int c = 0; c < kCols; ++c) xs[c + 1] = xs[c] + 5 + 4 * r.uniform();
  for (int c = 0; c < kRows; ++c) ys[c + 1] = ys[c] + 4 + 3 * r.uniform();
  const double height = 2.6 + 0.6 * r.uniform();
  for (int j = 0; j < kRows; ++j) {
    for (int i = 0; i < kCols; ++i) {
      Room room;
      room.lo[0] = xs[i] + kWall / 2, room.hi[0] = xs[i + 1] - kWall / 2;
      room.lo[1] = ys[j] + kWall / 2, room.hi[1] = ys[j + 1] - kWall / 2;
      room.lo[2] = 0, room.hi[2] = height;
      for (int c = 0; c < 2; ++c) room.scanner[c] = room.lo[c] + 1 + (room.hi[c] - room.lo[c] - 2) * r.uniform();
      room.scanner[2] = 1.5;
      rooms_.push_back(room);
    }
  }
}

void IndoorScan::point(std::uint64_t i, double* p) const {
  PointRng r(key_point_, i);
  const Room& room = rooms_[std::min(rooms_.size() - 1, std::size_t(r.uniform() * double(rooms_.size())))];
  double d[3];
  do r.direction(d);
  while (d[2] < -0.95);  // the tripod hides the floor right under the scanner
  // The first plane the ray meets: the room is a box around the scanner.
  double t = 1e300;
  for (int c = 0; c < 3; ++c) {
    if (d[c] > 0)
      t = std::min(t, (room.hi[c] - room.scanner[c]) / d[c]);
    else if (d[c] < 0)
      t = std::min(t, (room.lo[c] - room.scanner[c]) / d[c]);
  }
  t += 0.002 * r.symmetric();  // range noise
  for (int c = 0; c < 3; ++c) p[c] = millimetres(room.scanner[c] + t * d[c]);
}

}  // namespace tetstream::io
