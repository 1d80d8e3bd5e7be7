// Every writer keeps the promises `run` keeps, and verify's volume check is a proof
// (issue #35): the one way to open an output (io/output_file.hpp) refuses inputs and
// files the user did not name, work files are made new (never through a planted link),
// a work directory is recognised by a marker written in that very directory, and the
// volume comparison holds for near-flat point sets.
#include "core/error.hpp"
#include "io/output_file.hpp"
#include "io/point_writer.hpp"
#include "pipeline/files/temp_files.hpp"
#include "pipeline/verify/exact_sum.hpp"
#include "pipeline/files/work_dir.hpp"
#include "scratch_dir.hpp"

#include <gtest/gtest.h>

#include <cfloat>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

using namespace tetstream;
using tetstream::testing_util::ScratchDirTest;

namespace {

class WriterSafety : public ScratchDirTest {
 protected:
  WriterSafety() : ScratchDirTest("writer-safety") { io::note_files(true); }
  void TearDown() override {
    io::forget_noted_files();
    io::note_files(false);
    ScratchDirTest::TearDown();
  }
  void put(const std::string& name, const std::string& text) {
    std::FILE* f = std::fopen(path(name).c_str(), "wb");  // test fixture, not the tool
    ASSERT_NE(f, nullptr);
    std::fwrite(text.data(), 1, text.size(), f);
    std::fclose(f);
  }
  std::string get(const std::string& name) {
    std::ifstream in(path(name), std::ios::binary);
    return {std::istreambuf_iterator<char>(in), {}};
  }
};

TEST_F(WriterSafety, AnOutputIsNeverAFileTheCommandReads) {
  put("points.f64", "precious");
  io::note_input(path("points.f64"));
  EXPECT_THROW(io::OutputFile(path("points.f64")), UsageError);
  // A hard link to it under another name: the same file.
  ASSERT_EQ(::link(path("points.f64").c_str(), path("other.json").c_str()), 0);
  EXPECT_THROW(io::OutputFile(path("other.json")), UsageError);
  EXPECT_EQ(get("points.f64"), "precious");
}

TEST_F(WriterSafety, AFinishedOutputIsNotReplacedByALaterOneOfTheSameProcess) {
  {
    io::OutputFile f(path("o.tets"));
    f.write("container");
    f.commit();
  }
  EXPECT_THROW(io::OutputFile(path("o.tets")), UsageError);  // --json-file o.tets
  EXPECT_EQ(get("o.tets"), "container");
}

TEST_F(WriterSafety, AFileBesideTheNamedOneIsNotTheUsers) {
  put("snap.h5", "snapshot");
  // snap.xdmf does not exist: snap.h5 is not an earlier output beside it.
  EXPECT_THROW(io::OutputClaim(path("snap.h5"), io::OutputClaim::Kind::kBeside, path("snap.xdmf")), UsageError);
  EXPECT_EQ(get("snap.h5"), "snapshot");
  // A rerun: both files there, the pair is replaced.
  put("snap.xdmf", "<Xdmf/>");
  EXPECT_NO_THROW(io::OutputClaim(path("snap.h5"), io::OutputClaim::Kind::kBeside, path("snap.xdmf")));
}

TEST_F(WriterSafety, PointWriterRefusesLinksAndASecondWriter) {
  put("victim.txt", "victim");
  ASSERT_EQ(::symlink(path("victim.txt").c_str(), path("out.f64.partial").c_str()), 0);
  EXPECT_THROW(io::create_points(path("out.f64"), {}, 1), UsageError);
  EXPECT_EQ(get("victim.txt"), "victim");
  ::unlink(path("out.f64.partial").c_str());
  // A hard link planted as the partial file.
  ASSERT_EQ(::link(path("victim.txt").c_str(), path("out.f64.partial").c_str()), 0);
  EXPECT_THROW(io::create_points(path("out.f64"), {}, 1), UsageError);
  EXPECT_EQ(get("victim.txt"), "victim");
  ::unlink(path("out.f64.partial").c_str());
  // An output that is a link.
  ASSERT_EQ(::symlink(path("victim.txt").c_str(), path("link.f64").c_str()), 0);
  EXPECT_THROW(io::create_points(path("link.f64"), {}, 1), UsageError);
  // Two writers of one output: the second is refused while the first holds it.
  auto first = io::create_points(path("two.f64"), {}, 1);
  EXPECT_THROW(io::create_points(path("two.f64"), {}, 1), UsageError);
  const double p[3] = {1, 2, 3};
  first->write(p, 1);
  first->commit();
  EXPECT_EQ(get("two.f64").size(), 24u);
}

TEST_F(WriterSafety, WorkFilesAreMadeNewNeverThroughALink) {
  put("victim.txt", "victim");
  for (const char* name : {"state.json.tmp", "pending-3.tets.tmp", "hull.labels.tmp", "points-2.run"}) {
    ASSERT_EQ(::symlink(path("victim.txt").c_str(), path(name).c_str()), 0);
    {
      pipeline::BinaryFile f(path(name), "wb");
      f.write("new", 1, 3);
      f.close();
    }
    EXPECT_EQ(get("victim.txt"), "victim") << name;
    EXPECT_EQ(get(name), "new") << name;
    struct stat st {};
    ASSERT_EQ(::lstat(path(name).c_str(), &st), 0);
    EXPECT_TRUE(S_ISREG(st.st_mode)) << name;
  }
  // A hard link: replaced by a new file, the other name keeps its bytes.
  ASSERT_EQ(::link(path("victim.txt").c_str(), path("hard.tmp").c_str()), 0);
  ::close(io::create_work_file(path("hard.tmp")));
  EXPECT_EQ(get("victim.txt"), "victim");
}

TEST_F(WriterSafety, ACopiedMarkerDoesNotMakeAWorkDirectory) {
  std::string made;
  {
    pipeline::WorkDir w = pipeline::WorkDir::create_unique(dir_.string(), "tetstream-run");
    made = w.dir();
  }
  // The job that made it died: it is stale, and found.
  ASSERT_EQ(pipeline::find_stale_work_dirs(dir_.string()).size(), 1u);
  // The user's directory with a copy of its marker and files named like work files.
  const std::string mine = path("thesis");
  ASSERT_EQ(::mkdir(mine.c_str(), 0700), 0);
  const std::string marker = made + "/" + pipeline::WorkDir::kMarker;
  std::ifstream in(marker, std::ios::binary);
  const std::string text{std::istreambuf_iterator<char>(in), {}};
  put("thesis/.tetstream-workdir", text);
  put("thesis/state.json", "{\"mine\": true}");
  put("thesis/points-1.run", "chapter 1");
  const auto stale = pipeline::find_stale_work_dirs(dir_.string());
  ASSERT_EQ(stale.size(), 1u);
  EXPECT_EQ(stale[0].path, made);
  EXPECT_THROW(pipeline::WorkDir::open_or_create(mine), UsageError);
  for (const auto& s : stale) EXPECT_TRUE(pipeline::remove_stale_work_dir(s));
  EXPECT_EQ(get("thesis/state.json"), "{\"mine\": true}");
  EXPECT_EQ(get("thesis/points-1.run"), "chapter 1");
}

// A named work directory appears whole (made under PATH.new-XXXXXX, marked, renamed):
// it is never seen unmarked, nothing is left beside it, and an empty directory of the
// user's at PATH is refused and kept, not replaced by the rename.
TEST_F(WriterSafety, ANamedWorkDirectoryAppearsMarkedAndReplacesNothing) {
  const std::string ckpt = path("out.tets.ckpt");
  {
    pipeline::WorkDir w = pipeline::WorkDir::open_or_create(ckpt);
    EXPECT_EQ(w.dir(), ckpt);
    struct stat st {};
    EXPECT_EQ(::lstat((ckpt + "/" + pipeline::WorkDir::kMarker).c_str(), &st), 0);
    std::vector<std::string> names;
    for (const auto& e : std::filesystem::directory_iterator(dir_)) names.push_back(e.path().filename().string());
    EXPECT_EQ(names, std::vector<std::string>{"out.tets.ckpt"});
  }
  // Reopened by a later process (the marker names this directory).
  { pipeline::WorkDir again = pipeline::WorkDir::open_or_create(ckpt); }
  const std::string mine = path("empty-of-mine");
  ASSERT_EQ(::mkdir(mine.c_str(), 0700), 0);
  EXPECT_THROW(pipeline::WorkDir::open_or_create(mine), UsageError);
  EXPECT_TRUE(std::filesystem::is_empty(mine));
}

// A named work directory disappears whole: removed under another name (PATH.old-PID-N),
// so a kill while it is emptied leaves PATH intact or gone, never an unmarked PATH that
// --resume would refuse. Removed, nothing is left beside it; with a file of the user's
// in it, it stays at PATH with that file.
TEST_F(WriterSafety, ANamedWorkDirectoryDisappearsWholeAndKeepsWhatIsNotOurs) {
  const std::string ckpt = path("out.tets.ckpt");
  {
    pipeline::WorkDir w = pipeline::WorkDir::open_or_create(ckpt);
    put("out.tets.ckpt/state.json", "{}");
    put("out.tets.ckpt/sorted.points", "points");
    EXPECT_TRUE(w.remove());
  }
  EXPECT_TRUE(std::filesystem::is_empty(dir_));
  {
    pipeline::WorkDir w = pipeline::WorkDir::open_or_create(ckpt);
    put("out.tets.ckpt/state.json", "{}");
    put("out.tets.ckpt/notes.txt", "mine");
    EXPECT_FALSE(w.remove());
    EXPECT_EQ(w.dir(), ckpt);
  }
  EXPECT_EQ(get("out.tets.ckpt/notes.txt"), "mine");
  struct stat st {};
  EXPECT_NE(::lstat(path("out.tets.ckpt/state.json").c_str(), &st), 0);
  std::vector<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(dir_)) names.push_back(e.path().filename().string());
  EXPECT_EQ(names, std::vector<std::string>{"out.tets.ckpt"});
}

TEST_F(WriterSafety, AMissingParentOfTheWorkDirectoryIsSaid) {
  try {
    pipeline::WorkDir::open_or_create(path("missing/out.tets.ckpt"));
    FAIL() << "no error";
  } catch (const UsageError& e) {
    EXPECT_NE(std::string(e.what()).find("does not exist"), std::string::npos) << e.what();
  }
}

TEST(ExactSum, SubtractIsExact) {
  using pipeline::verify_engine::ExactSum;
  ExactSum a, b;
  a.add(1e300L), a.add(3e-300L), b.add(1e300L);
  a.subtract(b);
  EXPECT_EQ(a.value(), 3e-300L);
  ExactSum c;
  c.add(1.0), c.subtract(a);
  EXPECT_EQ(c.value(), 1.0L - 3e-300L);  // rounded towards zero
}

// Near-flat tets: the computed determinant may be far from the exact one, but never
// by more than the bound.
TEST(BoundedDet, BoundCoversTheRoundingOfNearFlatTets) {
  using pipeline::verify_engine::det3_bounded;
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> u(0, 1);
  for (int i = 0; i < 20000; ++i) {
    double p[4][3];
    for (auto& q : p) q[0] = u(rng), q[1] = u(rng), q[2] = 0.1 * q[0] + 0.3 * q[1];
    const auto d = det3_bounded<double>(p[0], p[1], p[2], p[3]);
    // The exact determinant, in long double from exact differences' products is not
    // exact either; compare the double value with the long double one within the bound.
    const auto wide = det3_bounded<long double>(p[0], p[1], p[2], p[3]);
    EXPECT_LE(std::fabs((long double)d.value - wide.value), (long double)d.error + wide.error);
  }
}

}  // namespace
