// `run --periodic` through its API (pipeline/periodic/periodic.hpp) and `verify` of a
// periodic container: degenerate sets (a lattice, cospherical points) verify clean, the
// bytes do not depend on threads or segments' count... of the budget's segments, points
// outside the box are wrapped or refused, and a reader that does not know periodic
// containers refuses one. The comparison with CGAL is in tests/cgal/.
#include "core/error.hpp"
#include "io/tet_container.hpp"
#include "io/tet_periodic.hpp"
#include "io/tet_reader.hpp"
#include "io/tet_writer.hpp"
#include "pipeline/periodic/field.hpp"
#include "pipeline/periodic/periodic.hpp"
#include "pipeline/periodic/verify.hpp"
#include "periodic_sets.hpp"
#include "scratch_dir.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>

namespace tetstream {
namespace {

using pipeline::periodic::PeriodicOptions;

class Periodic : public testing_util::ScratchDirTest {
 protected:
  Periodic() : ScratchDirTest("periodic") {}

  pipeline::periodic::PeriodicSummary run(const std::vector<double>& xyz, const std::string& out, int threads = 1,
                                          std::uint64_t segment_points = 0, bool wrap = true) {
    const std::string in = path("points.f64");
    testing_util::write_f64(in, xyz);
    pipeline::RunOptions o;
    o.input = in;
    o.output = path(out);
    o.threads = threads;
    o.segment_points = segment_points;
    o.progress = false;
    PeriodicOptions p;
    p.period = {1, 1, 1};
    p.wrap = wrap;
    return pipeline::periodic::run_periodic(o, p);
  }
  pipeline::periodic::PeriodicVerifyReport verify(const std::string& out) {
    return pipeline::periodic::verify_periodic(path(out), std::uint64_t(64) << 20, dir_.string());
  }
  std::string bytes(const std::string& out) {
    std::ifstream f(path(out), std::ios::binary);
    return {std::istreambuf_iterator<char>(f), {}};
  }
};

void expect_clean(const pipeline::periodic::PeriodicVerifyReport& r, std::uint64_t points) {
  EXPECT_TRUE(r.ok) << r.problem;
  EXPECT_EQ(r.points, points);
  EXPECT_EQ(r.vertices, points);
  EXPECT_EQ(r.euler, 0);
  EXPECT_EQ(r.facets, 2 * r.tets);
  EXPECT_EQ(r.unpaired + r.not_delaunay + r.bad_orientation + r.inexact, 0u);
}

TEST_F(Periodic, LatticeVerifiesClean) {
  // Every tet of the lattice's Delaunay triangulation is one of many cospherical
  // choices: the perturbation must pick the same one for a point and its images.
  const auto s = run(testing_util::lattice(8), "lattice.tets");
  EXPECT_EQ(s.points, 512u);
  expect_clean(verify("lattice.tets"), 512);
}

TEST_F(Periodic, CosphericalVerifiesClean) {
  auto xyz = testing_util::dyadic_uniform(1500, 3);
  const auto sphere = testing_util::cospherical_48();
  xyz.insert(xyz.end(), sphere.begin(), sphere.end());
  const auto s = run(xyz, "sphere.tets", 1, 300);
  EXPECT_EQ(s.points, 1548u);
  expect_clean(verify("sphere.tets"), 1548);
}

TEST_F(Periodic, UniformVerifiesCleanAndBytesDoNotDependOnThreads) {
  const auto xyz = testing_util::dyadic_uniform(3000, 7);
  const auto one = run(xyz, "one.tets", 1, 400);
  const auto two = run(xyz, "two.tets", 2, 400);
  EXPECT_GE(one.padded.segments, 5u);
  EXPECT_EQ(one.tets, two.tets);
  EXPECT_EQ(bytes("one.tets"), bytes("two.tets"));
  expect_clean(verify("one.tets"), 3000);
}

TEST_F(Periodic, TheBudgetsSegmentsGiveTheSameTets) {
  const auto xyz = testing_util::dyadic_uniform(2000, 9);
  run(xyz, "few.tets", 1, 0);
  run(xyz, "many.tets", 1, 250);
  EXPECT_EQ(testing_util::container_periodic_keys(path("few.tets")),
            testing_util::container_periodic_keys(path("many.tets")));
}

TEST_F(Periodic, PointsOutsideTheBoxAreWrappedOrRefused) {
  auto xyz = testing_util::dyadic_uniform(2000, 5);
  auto shifted = xyz;
  for (std::size_t i = 0; i < shifted.size(); i += 7) shifted[i] += (i % 2 ? 1.0 : -2.0);
  run(xyz, "inside.tets");
  const auto s = run(shifted, "wrapped.tets");
  EXPECT_GT(s.wrapped, 0u);
  EXPECT_EQ(testing_util::container_periodic_keys(path("inside.tets")),
            testing_util::container_periodic_keys(path("wrapped.tets")));
  try {
    run(shifted, "refused.tets", 1, 0, false);
    FAIL() << "a point outside the box was not refused";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("lies outside [0, 1)"), std::string::npos) << e.what();
  }
}

// A raw float64 input inside the box is the padded job's input as it is; one -0.0 (made
// 0.0 by the wrap) or one point outside makes the wrapped copy, and the same bytes.
TEST_F(Periodic, AnInputInsideTheBoxIsReadInPlace) {
  auto xyz = testing_util::dyadic_uniform(2000, 6);
  xyz[3 * 17 + 1] = 0.0;
  EXPECT_FALSE(run(xyz, "in_place.tets", 1, 300).input_copied);
  const std::string in_place = bytes("in_place.tets");
  xyz[3 * 17 + 1] = -0.0;
  EXPECT_TRUE(run(xyz, "minus_zero.tets", 1, 300).input_copied);
  EXPECT_EQ(bytes("minus_zero.tets"), in_place);
  xyz[3 * 17 + 1] = 1.0;  // wrapped to 0.0
  const auto wrapped = run(xyz, "wrapped.tets", 1, 300);
  EXPECT_TRUE(wrapped.input_copied);
  EXPECT_EQ(wrapped.wrapped, 1u);
  EXPECT_EQ(bytes("wrapped.tets"), in_place);
  EXPECT_TRUE(std::filesystem::exists(path("points.f64")));  // the input, only read
}

TEST_F(Periodic, DuplicatesAfterWrappingAreMerged) {
  // The lattice plus copies of its x = 0 face at x = 1: wrapped onto the face, merged.
  auto xyz = testing_util::lattice(8);
  for (std::size_t i = 0; i < 64; ++i) xyz.insert(xyz.end(), {1.0, xyz[3 * i + 1], xyz[3 * i + 2]});
  const auto s = run(xyz, "dup.tets");
  EXPECT_EQ(s.padded.input_points - s.padded.points, s.padded.duplicates);
  EXPECT_EQ(s.points, 512u);
  expect_clean(verify("dup.tets"), 512);
}

TEST_F(Periodic, TooFewPointsForOneSheetAreRefused) {
  try {
    run(testing_util::dyadic_uniform(12, 4), "few.tets");
    FAIL() << "12 points in a box were triangulated in one sheet";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("1-sheeted"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(path("few.tets")));
  EXPECT_FALSE(std::filesystem::exists(path("few.tets.partial")));
}

TEST_F(Periodic, AReaderOfPlainTetsRefusesAPeriodicContainer) {
  run(testing_util::dyadic_uniform(2000, 1), "p.tets");
  try {
    io::TetReader r(path("p.tets"));
    FAIL() << "a periodic container was read as a plain one";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("periodic"), std::string::npos) << e.what();
  }
  const io::TetReader r(path("p.tets"), io::TetReader::Periodic::kAccept);
  EXPECT_TRUE(r.periodic());
}

TEST_F(Periodic, DtfeHasNoHullAndConservesMass) {
  // On the torus every point has a closed star: a density for each, none NaN; the
  // mass sum N to 1e-12; Voronoi cells tiling the box; a grid with no NaN.
  run(testing_util::dyadic_uniform(4000, 8), "d.tets");
  pipeline::periodic::PeriodicFieldOptions o;
  o.prefix = path("f");
  o.density = o.voronoi = true;
  o.grid = {24, 24, 24};
  const auto r = pipeline::periodic::periodic_field(path("d.tets"), o);
  EXPECT_EQ(r.points, 4000u);
  EXPECT_EQ(r.nan_points, 0u);
  EXPECT_EQ(r.nan_cells, 0u);
  EXPECT_NEAR(r.mass_check, 4000.0, 1e-12 * 4000);
  EXPECT_NEAR(r.star_sum, 4.0, 1e-12);
  EXPECT_NEAR(r.voronoi_sum, 1.0, 1e-12);
  EXPECT_EQ(r.files.size(), 3u);
}

TEST_F(Periodic, AWrongOffsetIsFound) {
  // The same container rewritten with one vertex moved by a period: verify must see
  // facets that no longer close up (and the volume, and Euler).
  run(testing_util::dyadic_uniform(2000, 2), "p.tets");
  {
    const io::TetReader r(path("p.tets"), io::TetReader::Periodic::kAccept);
    const io::PeriodicOffsetsReader offsets(r);
    io::TetWriter w(path("bad.tets"), r.header());
    std::vector<double> xyz(3 * r.point_count());
    std::vector<std::uint64_t> ids(r.point_count()), labels;
    r.read_points(0, ids.size(), xyz.data(), ids.data());
    w.add_points(xyz.data(), ids.data(), ids.size());
    const auto box = r.section(io::kTagPeriodicBox);
    w.add_section(io::kTagPeriodicBox, box);
    io::PeriodicOffsetsWriter ow;
    std::vector<std::uint16_t> codes;
    for (std::uint64_t f = 0; f < r.frame_count(); ++f) {
      r.read_frame(f, labels);
      offsets.read(f, codes);
      if (f == 0) codes[0] = std::uint16_t(codes[0] ^ 1);  // vertex c one period further in z
      w.add_tets(std::span<const std::uint64_t>(labels));
      ow.add_frame(codes);
    }
    w.add_section(io::kTagPeriodicOffsets, ow.payload());
    w.finish();
  }
  const auto r = verify("bad.tets");
  EXPECT_FALSE(r.ok);
  EXPECT_GT(r.unpaired, 0u);
}

}  // namespace
}  // namespace tetstream
