// The writer stage behind a bounded queue (pipeline/async_tet_writer, pipeline/bounded_queue)
// and partial files kept for resumable jobs (TetWriterOptions::keep_partial).
//
// Failures are real: RLIMIT_FSIZE caps the file size (SIGXFSZ ignored), so write()
// fails with EFBIG and io::OutputFile throws IoError on the writer's thread. Every test
// runs under an alarm() watchdog, so a hang fails the test instead of stalling the suite.
// Tets are random label quadruples (the writer checks labels, not geometry).
#include "core/error.hpp"
#include "io/output_file.hpp"
#include "io/tet_writer.hpp"
#include "pipeline/write/async_tet_writer.hpp"
#include "pipeline/util/bounded_queue.hpp"
#include "scratch_dir.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <csignal>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>
#include <sys/resource.h>
#include <thread>
#include <unistd.h>
#include <vector>

namespace fs = std::filesystem;
using namespace tetstream;
using pipeline::AsyncTetWriter;
using pipeline::BoundedQueue;

namespace {

// ---------------------------------------------------------------- fixtures

// A hang (a lost wake-up, a join that never returns) kills the test after a minute.
// Its files go in a scratch directory of the test's own, removed with all it holds
// (pipeline::TempDir would remove only the names a job makes, and left these behind).
class Watchdog : public testing_util::ScratchDirTest {
 protected:
  Watchdog() : ScratchDirTest("async-writer") {}
  void SetUp() override {
    ScratchDirTest::SetUp();
    ::alarm(60);
  }
  void TearDown() override {
    ::alarm(0);
    ScratchDirTest::TearDown();
  }
};
using KeepPartial = Watchdog;
using BoundedQueueTest = Watchdog;
using AsyncTetWriterTest = Watchdog;

// Caps the size of files this process writes; restores the limit and SIGXFSZ after.
class FileSizeLimit {
 public:
  explicit FileSizeLimit(std::uint64_t bytes) {
    ::getrlimit(RLIMIT_FSIZE, &saved_);
    old_handler_ = std::signal(SIGXFSZ, SIG_IGN);  // write() then fails with EFBIG
    rlimit r = saved_;
    r.rlim_cur = rlim_t(bytes);
    EXPECT_EQ(::setrlimit(RLIMIT_FSIZE, &r), 0);
  }
  ~FileSizeLimit() { lift(); }
  void lift() {
    if (lifted_) return;
    lifted_ = true;
    EXPECT_EQ(::setrlimit(RLIMIT_FSIZE, &saved_), 0);
    std::signal(SIGXFSZ, old_handler_);
  }

 private:
  rlimit saved_{};
  void (*old_handler_)(int) = SIG_DFL;
  bool lifted_ = false;
};

// ---------------------------------------------------------------- jobs

struct Job {
  io::TetFileHeader header;
  std::vector<double> xyz;
  std::vector<std::vector<std::uint64_t>> batches;  // 4 labels per tet
};

Job make_job(std::size_t points, const std::vector<std::size_t>& batch_tets, std::uint64_t seed) {
  Job job;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (std::size_t i = 0; i < 3 * points; ++i) job.xyz.push_back(unit(rng));
  job.header.point_count = points;
  job.header.input_count = points;
  job.header.bbox_min = {0, 0, 0};
  job.header.bbox_max = {1, 1, 1};
  job.header.tool = "tetstream-test";
  job.header.options = R"({"test":"async"})";
  for (const std::size_t n : batch_tets) {
    std::vector<std::uint64_t> b;
    while (b.size() < 4 * n) {
      std::uint64_t t[4];
      for (int s = 0; s < 4; ++s) {
        bool again = true;
        while (again) {
          t[s] = rng() % points;
          again = false;
          for (int r = 0; r < s; ++r) again = again || t[r] == t[s];
        }
      }
      b.insert(b.end(), t, t + 4);
    }
    job.batches.push_back(std::move(b));
  }
  return job;
}

std::unique_ptr<io::TetWriter> open_writer(const std::string& path, const Job& job, const io::TetWriterOptions& o) {
  auto w = std::make_unique<io::TetWriter>(path, job.header, o);
  w->add_points(job.xyz.data(), nullptr, job.header.point_count);
  return w;
}

// The reference: every batch straight into TetWriter::add_tets.
void write_directly(const std::string& path, const Job& job, const io::TetWriterOptions& o) {
  auto w = open_writer(path, job, o);
  for (const auto& b : job.batches) w->add_tets(std::span<const std::uint64_t>(b));
  w->finish();
}

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

io::TetWriterOptions small_frames() {
  io::TetWriterOptions o;
  o.frame_tets = 300;  // batches split into several frames, as in a real job
  o.sync = false;
  return o;
}

// What the producer saw, one letter a call: '.' returned, 'I' IoError, 'L' logic_error,
// 'X' anything else. A failure reported exactly once, and nothing after it but the
// short logic errors, reads ".*IL*" (dots, one I, then only Ls).
struct Outcome {
  std::string calls;
  std::string io_message;
  bool reported_once() const {
    const std::size_t i = calls.find('I');
    return i != std::string::npos && calls.find_first_not_of('.') == i &&
           calls.find_first_not_of('L', i + 1) == std::string::npos;
  }
};

template <class F>
void record(Outcome& out, F&& call) {
  try {
    call();
    out.calls += '.';
  } catch (const IoError& e) {
    out.calls += 'I';
    out.io_message = e.what();
  } catch (const std::logic_error&) {
    out.calls += 'L';
  } catch (...) {
    out.calls += 'X';
  }
}

// ---------------------------------------------------------------- keep_partial

TEST_F(KeepPartial, OutputFileRemovesThePartialFileUnlessKept) {
  const std::string path = this->path("plain.bin");
  {
    io::OutputFile f(path);
    f.write("abc");
    f.flush();
    EXPECT_TRUE(fs::exists(path + ".partial"));
  }
  EXPECT_FALSE(fs::exists(path + ".partial"));  // the default, as before

  {
    io::OutputFile f(path);
    f.keep_on_failure(true);
    f.write("abc");
    f.flush();
    f.write("def");  // buffered only: a failing job's destructor does not flush
  }
  EXPECT_FALSE(fs::exists(path));
  EXPECT_EQ(slurp(path + ".partial"), "abc");
  {
    auto f = io::OutputFile::reopen(path, 2);
    f->keep_on_failure(true);
    f->write("X");
    f->flush();
  }
  EXPECT_EQ(slurp(path + ".partial"), "abX");
  {
    auto f = io::OutputFile::reopen(path, 3);  // not kept: removed, as before
  }
  EXPECT_FALSE(fs::exists(path + ".partial"));
  {
    io::OutputFile f(path);
    f.keep_on_failure(true);
    f.write("done");
    f.commit(false);
  }
  EXPECT_EQ(slurp(path), "done");
  EXPECT_FALSE(fs::exists(path + ".partial"));
}

// discard() under a claim (the periodic keep step when a margin doubles): the claimed
// file is emptied and stays for the next writer, which starts it over and commits; a
// claim whose job ends after a discard removes the empty file it made.
TEST_F(KeepPartial, DiscardEmptiesTheClaimedFileForTheNextWriter) {
  const std::string path = this->path("claimed.bin");
  {
    io::OutputClaim claim(path);
    {
      io::OutputFile f(path, std::size_t(1) << 16, &claim);
      f.write("first attempt");
      f.flush();
      f.write("buffered");
      f.discard();
    }
    ASSERT_TRUE(fs::exists(path + ".partial"));
    EXPECT_EQ(fs::file_size(path + ".partial"), 0u);
    {
      io::OutputFile f(path, std::size_t(1) << 16, &claim);
      f.write("second");
      f.commit(false);
    }
  }
  EXPECT_EQ(slurp(path), "second");
  EXPECT_FALSE(fs::exists(path + ".partial"));

  const std::string gone = this->path("refused.bin");
  {
    io::OutputClaim claim(gone);
    io::OutputFile f(gone, std::size_t(1) << 16, &claim);
    f.write("points");
    f.flush();
    f.discard();
  }
  EXPECT_FALSE(fs::exists(gone + ".partial"));
  EXPECT_FALSE(fs::exists(gone));
}

TEST_F(KeepPartial, TetWriterKeepsThePartialFileForAResume) {
  const Job job = make_job(2000, {700, 500, 900, 400}, 1);
  const std::string whole = this->path("whole.tets"), path = this->path("job.tets");
  io::TetWriterOptions o = small_frames();
  write_directly(whole, job, o);

  // Default: an unfinished writer removes its file.
  {
    auto w = open_writer(path, job, o);
    w->add_tets(std::span<const std::uint64_t>(job.batches[0]));
    w->checkpoint();
  }
  EXPECT_FALSE(fs::exists(path + ".partial"));

  // keep_partial: the file survives, and a resume from the checkpoint completes the job.
  o.keep_partial = true;
  std::uint64_t committed = 0;
  {
    auto w = open_writer(path, job, o);
    w->add_tets(std::span<const std::uint64_t>(job.batches[0]));
    w->add_tets(std::span<const std::uint64_t>(job.batches[1]));
    committed = w->checkpoint();
    w->add_tets(std::span<const std::uint64_t>(job.batches[2]));  // after the checkpoint: dropped
  }
  ASSERT_TRUE(fs::exists(path + ".partial"));
  EXPECT_GE(fs::file_size(path + ".partial"), committed);

  // A resume refused by its checks keeps the file too (resume honours the option) ...
  io::TetFileHeader other = job.header;
  other.options = "{}";
  EXPECT_THROW(io::TetWriter::resume(path, other, committed, o), InputError);
  ASSERT_TRUE(fs::exists(path + ".partial"));
  // ... and an unfinished resumed writer as well.
  {
    auto w = io::TetWriter::resume(path, job.header, committed, o);
    w->add_tets(std::span<const std::uint64_t>(job.batches[2]));
  }
  ASSERT_TRUE(fs::exists(path + ".partial"));

  auto w = io::TetWriter::resume(path, job.header, committed, o);
  EXPECT_EQ(w->tets_written(), 1200u);
  w->add_tets(std::span<const std::uint64_t>(job.batches[2]));
  w->add_tets(std::span<const std::uint64_t>(job.batches[3]));
  w->finish();
  EXPECT_FALSE(fs::exists(path + ".partial"));
  EXPECT_EQ(slurp(path), slurp(whole));

  // Without the option a refused resume removes the file, as before.
  {
    auto v = open_writer(path, job, o);
    committed = v->checkpoint();
  }
  o.keep_partial = false;
  EXPECT_THROW(io::TetWriter::resume(path, other, committed, o), InputError);
  EXPECT_FALSE(fs::exists(path + ".partial"));
}

// ---------------------------------------------------------------- BoundedQueue

TEST_F(BoundedQueueTest, CloseDrainsAndCancelDrops) {
  BoundedQueue<std::vector<int>> q(3);
  EXPECT_THROW(BoundedQueue<int>(0), std::invalid_argument);
  for (int i = 0; i < 3; ++i) EXPECT_TRUE(q.push(std::vector<int>{i, i}));
  EXPECT_EQ(q.size(), 3u);
  EXPECT_EQ(q.peak_size(), 3u);
  q.close();
  q.close();  // idempotent
  std::vector<int> late{9};
  EXPECT_FALSE(q.push(std::move(late)));
  EXPECT_EQ(late, std::vector<int>{9});  // not taken: still the caller's
  std::vector<int> v;
  for (int i = 0; i < 3; ++i) {
    ASSERT_TRUE(q.pop(v));  // closed, but what was queued is still delivered, in order
    EXPECT_EQ(v, (std::vector<int>{i, i}));
  }
  EXPECT_FALSE(q.pop(v));
  EXPECT_TRUE(q.closed());

  BoundedQueue<std::vector<int>> c(2);
  EXPECT_TRUE(c.push(std::vector<int>{1}));
  EXPECT_TRUE(c.push(std::vector<int>{2}));
  c.cancel();
  EXPECT_TRUE(c.cancelled());
  EXPECT_EQ(c.size(), 0u);  // dropped
  EXPECT_FALSE(c.pop(v));
  EXPECT_FALSE(c.push(std::vector<int>{3}));
  c.close();  // after cancel: harmless
  EXPECT_FALSE(c.pop(v));
}

TEST_F(BoundedQueueTest, WakesBlockedProducersAndConsumers) {
  // A producer blocked on a full queue returns false when the queue is cancelled.
  BoundedQueue<int> full(1);
  ASSERT_TRUE(full.push(1));
  bool pushed = true;
  std::thread producer([&] { pushed = full.push(2); });
  full.cancel();
  producer.join();
  EXPECT_FALSE(pushed);

  // A consumer blocked on an empty queue returns false when the queue is closed.
  BoundedQueue<int> empty(1);
  bool popped = true;
  std::thread consumer([&] {
    int x = 0;
    popped = empty.pop(x);
  });
  empty.close();
  consumer.join();
  EXPECT_FALSE(popped);

  // A transfer through a small queue: everything arrives, in order, never more than 4 queued.
  BoundedQueue<std::uint64_t> q(4);
  constexpr std::uint64_t kCount = 20000;
  std::thread feeder([&] {
    for (std::uint64_t i = 0; i < kCount; ++i) {
      if (!q.push(std::uint64_t(i))) {
        ADD_FAILURE() << "push " << i << " refused";
        break;
      }
    }
    q.close();  // also after a failure: the consumer below must not wait forever
  });
  std::uint64_t next = 0, x = 0;
  while (q.pop(x)) {
    EXPECT_EQ(x, next);
    ++next;
  }
  feeder.join();
  EXPECT_EQ(next, kCount);
  EXPECT_LE(q.peak_size(), 4u);
  EXPECT_GE(q.peak_size(), 1u);
}

// ---------------------------------------------------------------- AsyncTetWriter

TEST_F(AsyncTetWriterTest, WritesTheSameBytesAsTheWriter) {
  // Odd sizes, an empty batch, batches below and above the frame size.
  const Job job = make_job(3000, {1000, 1, 0, 299, 300, 301, 2500, 17, 1200, 640, 0, 333}, 2);
  const io::TetWriterOptions o = small_frames();
  const std::string direct = this->path("direct.tets");
  std::uint64_t direct_checkpoint = 0;
  {
    auto w = open_writer(direct, job, o);
    for (std::size_t i = 0; i < job.batches.size(); ++i) {
      w->add_tets(std::span<const std::uint64_t>(job.batches[i]));
      if (i == 5) direct_checkpoint = w->checkpoint();
    }
    w->finish();
  }
  for (const std::size_t capacity : {1, 3}) {
    const std::string path = this->path("async-" + std::to_string(capacity) + ".tets");
    auto w = open_writer(path, job, o);
    AsyncTetWriter out(*w, capacity);
    for (std::size_t i = 0; i < job.batches.size(); ++i) {
      if (i % 2 == 0) {
        std::vector<std::uint64_t> b = out.take_buffer();
        EXPECT_TRUE(b.empty());
        b.assign(job.batches[i].begin(), job.batches[i].end());
        out.add_tets(std::move(b));
      } else {
        out.add_tets(std::span<const std::uint64_t>(job.batches[i]));  // copied
      }
      if (i == 5) {
        EXPECT_EQ(out.checkpoint(), direct_checkpoint);
      }
    }
    out.finish();
    EXPECT_EQ(slurp(path), slurp(direct)) << "capacity " << capacity;
    EXPECT_EQ(out.batches_written(), job.batches.size() - 2);  // the empty ones write nothing
    EXPECT_LE(out.peak_queued(), capacity);
    EXPECT_GE(out.peak_queued(), 1u);
    EXPECT_GE(out.busy_seconds(), 0.0);
    EXPECT_FALSE(out.failed());
    EXPECT_THROW(out.add_tets(out.take_buffer()), std::logic_error);  // after finish
    EXPECT_THROW(out.finish(), std::logic_error);
  }
}

TEST_F(AsyncTetWriterTest, GatheredBatchesAndQueuedCheckpointsWriteTheSameBytes) {
  // Batches taken several at a time (their frames encoded on the writer's threads) and
  // checkpoints queued between them: the bytes of one call per batch, and each
  // checkpoint reports the bytes the direct writer had at that point.
  const Job job = make_job(3000, {1000, 1, 0, 299, 300, 301, 2500, 17, 1200, 640, 0, 333}, 4);
  io::TetWriterOptions o = small_frames();
  const std::string direct = this->path("direct-gather.tets");
  std::vector<std::uint64_t> direct_checkpoints;
  {
    auto w = open_writer(direct, job, o);
    for (std::size_t i = 0; i < job.batches.size(); ++i) {
      w->add_tets(std::span<const std::uint64_t>(job.batches[i]));
      if (i % 3 == 2) direct_checkpoints.push_back(w->checkpoint());
    }
    w->finish();
  }
  o.threads = 3;
  for (const std::size_t gather : {1, 2, 3, 5}) {
    const std::string path = this->path("gather-" + std::to_string(gather) + ".tets");
    auto w = open_writer(path, job, o);
    AsyncTetWriter out(*w, 4, gather);
    std::vector<std::uint64_t> seen;  // written by the writer's thread, read after drain()
    for (std::size_t i = 0; i < job.batches.size(); ++i) {
      out.add_tets(std::span<const std::uint64_t>(job.batches[i]));
      if (i % 3 == 2) out.add_checkpoint([&seen](std::uint64_t committed) { seen.push_back(committed); });
    }
    out.drain();
    EXPECT_EQ(seen, direct_checkpoints) << "gather " << gather;
    out.finish();
    EXPECT_EQ(slurp(path), slurp(direct)) << "gather " << gather;
  }
}

TEST_F(AsyncTetWriterTest, AFailingCheckpointIsReportedOnce) {
  const Job job = make_job(1000, {400, 400, 400}, 5);
  auto w = open_writer(this->path("failing-checkpoint.tets"), job, small_frames());
  AsyncTetWriter out(*w, 2, 2);
  Outcome outcome;
  record(outcome, [&] { out.add_tets(std::span<const std::uint64_t>(job.batches[0])); });
  record(outcome,
         [&] { out.add_checkpoint([](std::uint64_t) { throw IoError("state.json: No space left on device"); }); });
  record(outcome, [&] { out.drain(); });
  record(outcome, [&] { out.add_tets(std::span<const std::uint64_t>(job.batches[1])); });
  record(outcome, [&] { out.finish(); });
  EXPECT_EQ(outcome.calls, "..ILL");
  EXPECT_TRUE(out.failed());
  EXPECT_THROW(out.add_checkpoint(nullptr), std::logic_error);  // used after the failure
}

TEST_F(AsyncTetWriterTest, RecyclesItsBuffers) {
  const Job job = make_job(1000, {400, 400, 400, 400, 400, 400}, 3);
  auto w = open_writer(this->path("recycle.tets"), job, small_frames());
  AsyncTetWriter out(*w, 2);
  std::vector<const std::uint64_t*> handed;  // the buffers given away
  for (const auto& b : job.batches) {
    std::vector<std::uint64_t> buf = out.take_buffer();
    buf.assign(b.begin(), b.end());
    handed.push_back(buf.data());
    out.add_tets(std::move(buf));
    EXPECT_TRUE(buf.empty());  // moved into the queue
  }
  out.drain();
  // Every batch is written and its buffer came back, its storage kept: a steady state
  // that allocates nothing. The spare list is bounded (capacity + 2).
  EXPECT_EQ(out.batches_written(), job.batches.size());
  std::size_t recycled = 0;
  for (int i = 0; i < 6; ++i) {
    std::vector<std::uint64_t> b = out.take_buffer();
    EXPECT_TRUE(b.empty());
    if (b.capacity() >= 1600 && std::find(handed.begin(), handed.end(), b.data()) != handed.end()) ++recycled;
  }
  EXPECT_GE(recycled, 1u);
  EXPECT_LE(recycled, 4u);
  out.finish();
}

TEST_F(AsyncTetWriterTest, ReportsMisuseOnTheProducerSide) {
  const Job job = make_job(500, {100, 100}, 4);
  auto w = open_writer(this->path("misuse.tets"), job, small_frames());
  AsyncTetWriter out(*w, 2);
  // Checked at once, on the caller's thread: nothing is queued.
  EXPECT_THROW(out.add_tets(std::vector<std::uint64_t>{1, 2, 3, 4, 5}), std::invalid_argument);
  out.add_tets(std::span<const std::uint64_t>(job.batches[0]));
  // Checked by the writer on the background thread: reported by the next call, once.
  out.add_tets(std::vector<std::uint64_t>{0, 1, 2, 500});  // label == point count
  EXPECT_THROW(out.drain(), std::invalid_argument);
  EXPECT_TRUE(out.failed());
  try {
    out.checkpoint();
    ADD_FAILURE() << "no error after a failure";
  } catch (const std::logic_error& e) {
    EXPECT_NE(std::string(e.what()).find("failed"), std::string::npos) << e.what();
  }
  EXPECT_THROW(out.finish(), std::logic_error);
  EXPECT_THROW(out.add_tets(std::span<const std::uint64_t>(job.batches[1])), std::logic_error);
}

TEST_F(AsyncTetWriterTest, DestroyedWithoutFinishStopsAndLeavesNoFile) {
  const Job job = make_job(2000, std::vector<std::size_t>(12, 1500), 5);
  const std::string path = this->path("abandoned.tets");
  {
    auto w = open_writer(path, job, small_frames());
    {
      AsyncTetWriter out(*w, 2);
      for (const auto& b : job.batches) out.add_tets(std::span<const std::uint64_t>(b));
      // No drain, no finish: the destructor cancels what is queued and joins.
    }
    EXPECT_TRUE(fs::exists(path + ".partial"));
    AsyncTetWriter again(*w, 1);
    again.add_tets(std::span<const std::uint64_t>(job.batches[0]));
    again.cancel();
    EXPECT_THROW(again.add_tets(std::span<const std::uint64_t>(job.batches[1])), std::logic_error);
    EXPECT_THROW(again.drain(), std::logic_error);
  }
  EXPECT_FALSE(fs::exists(path + ".partial"));
  EXPECT_FALSE(fs::exists(path));
}

// The disk fills while the producer keeps pushing: the IoError reaches it exactly once,
// every later call is a short logic_error, nothing blocks, the destructor returns.
Outcome push_until_the_disk_is_full(const Job& job, io::TetWriter& w, std::size_t capacity, std::uint64_t room) {
  const std::uint64_t committed = w.checkpoint();
  FileSizeLimit limit(committed + room);
  Outcome outcome;
  {
    AsyncTetWriter out(w, capacity);
    for (const auto& b : job.batches) record(outcome, [&] { out.add_tets(std::span<const std::uint64_t>(b)); });
    record(outcome, [&] { out.finish(); });
    EXPECT_TRUE(out.failed());
    EXPECT_GT(out.batches_written(), 0u);
  }
  return outcome;
}

TEST_F(AsyncTetWriterTest, DiskFullIsReportedOnceAndRemovesThePartialFile) {
  const Job job = make_job(50000, std::vector<std::size_t>(100, 2000), 6);
  const std::string path = this->path("full.tets");
  io::TetWriterOptions o = small_frames();
  o.buffer_bytes = 4096;  // small, so writes reach the file batch by batch
  Outcome outcome;
  {
    auto w = open_writer(path, job, o);
    outcome = push_until_the_disk_is_full(job, *w, 2, 64 << 10);
  }
  EXPECT_TRUE(outcome.reported_once()) << outcome.calls;
  // The room holds a few batches: the failure stops a producer that is still pushing
  // (blocked on the full queue, or about to be), and its later pushes return at once.
  EXPECT_LT(outcome.calls.find('I'), job.batches.size() / 2) << outcome.calls;
  EXPECT_NE(outcome.io_message.find("full.tets.partial"), std::string::npos) << outcome.io_message;
  EXPECT_FALSE(fs::exists(path + ".partial"));
  EXPECT_FALSE(fs::exists(path));
}

TEST_F(AsyncTetWriterTest, DiskFullSurfacesInCheckpoint) {
  // One batch, which cannot fit: add_tets() returns (nothing has failed yet when it is
  // called), and the failure comes out of the drain in checkpoint().
  const Job job = make_job(50000, {2000}, 7);
  const std::string path = this->path("drain.tets");
  io::TetWriterOptions o = small_frames();
  o.buffer_bytes = 4096;
  auto w = open_writer(path, job, o);
  const std::uint64_t committed = w->checkpoint();
  FileSizeLimit limit(committed + 1000);
  AsyncTetWriter out(*w, 8);
  Outcome outcome;
  record(outcome, [&] { out.add_tets(std::span<const std::uint64_t>(job.batches[0])); });
  record(outcome, [&] { out.checkpoint(); });
  record(outcome, [&] { out.finish(); });
  record(outcome, [&] { out.drain(); });
  EXPECT_EQ(outcome.calls, ".ILL");
}

TEST_F(AsyncTetWriterTest, DiskFullWithKeepPartialCanBeResumed) {
  const Job job = make_job(50000, std::vector<std::size_t>(40, 2000), 8);
  const std::string whole = this->path("whole.tets"), path = this->path("resumable.tets");
  io::TetWriterOptions o = small_frames();
  o.buffer_bytes = 4096;
  write_directly(whole, job, o);

  o.keep_partial = true;
  const std::size_t before = 5;  // batches written before the checkpoint
  std::uint64_t committed = 0;
  Outcome outcome;
  {
    auto w = open_writer(path, job, o);
    for (std::size_t i = 0; i < before; ++i) w->add_tets(std::span<const std::uint64_t>(job.batches[i]));
    committed = w->checkpoint();
    Job rest = job;
    rest.batches.erase(rest.batches.begin(), rest.batches.begin() + before);
    outcome = push_until_the_disk_is_full(rest, *w, 3, 100 << 10);
  }
  EXPECT_TRUE(outcome.reported_once()) << outcome.calls;
  ASSERT_TRUE(fs::exists(path + ".partial"));  // kept for --resume
  EXPECT_GE(fs::file_size(path + ".partial"), committed);

  // The disk has room again: resume at the checkpoint, through the async writer.
  auto w = io::TetWriter::resume(path, job.header, committed, o);
  {
    AsyncTetWriter out(*w, 2);
    for (std::size_t i = before; i < job.batches.size(); ++i)
      out.add_tets(std::span<const std::uint64_t>(job.batches[i]));
    out.finish();
  }
  EXPECT_EQ(slurp(path), slurp(whole));
  EXPECT_FALSE(fs::exists(path + ".partial"));
}

}  // namespace
