#pragma once
// The surface zoo behind `gen --dist hills|roofs|canopy|water|strips|scan-lines|survey|
// indoor`: the features of real 3D scans that make an out-of-core Delaunay certificate
// slow, each one alone and all together, so that no change is tuned to one shape.
//
// LidarTile is one composable airborne tile: a preset switches features on (relief,
// roofs, trees, holes, flight strips, scan lines) over the same ground model. IndoorScan
// is a terrestrial scan of closed rooms. Both are counter-based like the other
// generators (point i is a pure function of the seed, n and i, so any chunking on any
// thread gives the same points), keep only a few hundred numbers of state, and are
// public so that the tests can check each feature against the model that made it.
#include <cstdint>
#include <vector>

namespace tetstream::io {

namespace rng {
class PointRng;
}

// An airborne LiDAR tile in UTM-like coordinates, quantised to centimetres as a LAS
// file with scale 0.01 stores them. The tile is a square whose side follows n (about
// 3.3 returns a square metre where one strip covers the ground, the density of a
// scanner with 0.3 m between pulses along a scan line and 1 m between lines), at least
// 100 m, so small test sets keep their roofs and trees.
class LidarTile {
 public:
  enum class Preset { kHills, kRoofs, kCanopy, kWater, kStrips, kScanLines, kSurvey };

  static constexpr double kOffsetX = 500000, kOffsetY = 5000000, kOffsetZ = 200;
  static constexpr double kLineSpacing = 1.0;   // metres between scan lines
  static constexpr double kPulseSpacing = 0.3;  // metres between pulses along a line

  struct Features {
    double hill_amplitude = 12;    // metres, of the large waves of the ground
    double hill_wavelength = 700;  // metres
    double building_share = 0;     // of the 40 m cells that hold a building
    double tree_share = 0;         // of the 8 m cells that hold a tree
    bool lakes = false;            // lakes, and each building's scan shadow, with no returns
    bool strips = false;           // overlapping flight strips: bands of double density
    bool scan_lines = false;       // returns on lines across the flight direction
  };

  struct Building {
    double lo[2], hi[2];  // footprint, local metres
    double eave;          // flat roofs: the roof's height; gable roofs: the eaves'
    bool gable;           // a ridge along the longer side, 25-40 degree pitch
    double pitch;         // tan of the gable's slope
    double shadow;        // width of the scan shadow beyond the +x wall (with lakes)
  };
  struct Tree {
    double centre[2], radius, top, base;  // a spheroid crown from base to top
  };
  struct Lake {
    double centre[2], radii[2];
  };

  LidarTile(Preset preset, std::uint64_t seed, std::uint64_t n);

  const Features& features() const { return f_; }
  double side() const { return side_; }
  int strips() const { return int(strip_x0_.size()); }
  double strip_width() const { return strip_width_; }
  double strip_x0(int s) const { return strip_x0_[std::size_t(s)]; }
  const std::vector<Lake>& lakes() const { return lakes_; }

  // The model, in local metres (x, y in [0, side)); the output adds the offsets.
  double ground(double x, double y) const;
  // The building of 40 m cell (cx, cy), if any; eave and shadow only with heights.
  bool building(std::int64_t cx, std::int64_t cy, Building* b, bool heights = true) const;
  bool building_at(double x, double y, Building* b) const;  // footprint contains (x, y)
  double roof(const Building& b, double x, double y) const;
  bool tree_at(double x, double y, Tree* t) const;  // the highest crown over (x, y)
  bool in_hole(double x, double y) const;           // a lake or a building's shadow
  // The first-return height of a crown over (x, y), inside its disc.
  static double crown_top(const Tree& t, double x, double y);

  // Point i of the tile, output coordinates.
  void point(std::uint64_t i, double* p) const;

 private:
  void draw_xy(rng::PointRng& r, double* xy) const;
  bool tree_in_cell(std::int64_t cx, std::int64_t cy, Tree* t, bool heights) const;

  Features f_;
  double side_ = 0;
  double strip_width_ = 0;
  std::vector<double> strip_x0_, strip_line_phase_;
  std::vector<Lake> lakes_;
  double phase_[4] = {0, 0, 0, 0};
  std::uint64_t key_point_ = 0, key_pulse_ = 0, key_buildings_ = 0, key_trees_ = 0;
};

// A terrestrial laser scan of one storey: a row of closed rooms (floors, walls and
// ceilings, planes meeting at right angles; neighbouring rooms' walls 0.2 m apart),
// one scanner on a tripod 1.5 m up in each room. Each point is the first hit of a ray
// in a uniform direction, so its density falls with the square of the distance from
// its scanner, and with the grazing angle, as a real scan's does; the range has 2 mm of
// noise and the coordinates are quantised to millimetres. Local coordinates; the
// geometry does not depend on n.
class IndoorScan {
 public:
  struct Room {
    double lo[3], hi[3];  // the interior: floor at lo[2], ceiling at hi[2]
    double scanner[3];
  };

  explicit IndoorScan(std::uint64_t seed);
  const std::vector<Room>& rooms() const { return rooms_; }
  void point(std::uint64_t i, double* p) const;

 private:
  std::vector<Room> rooms_;
  std::uint64_t key_point_ = 0;
};

}  // namespace tetstream::io
