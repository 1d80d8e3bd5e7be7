#include "pipeline/util/memory_budget.hpp"

#include "core/error.hpp"

#include <algorithm>
#include <cmath>

namespace tetstream::pipeline {

namespace {

constexpr std::uint64_t kMiB = std::uint64_t(1) << 20;
// Bytes a point of a sorted run holds: its 32-byte record and the 24-byte coordinate
// copy that the hull candidates are computed from.
constexpr std::uint64_t kRunBytesPerPoint = 32 + 24;
// The hull pieces' kernels, per point of a piece (measured on a thin shell, where
// most of a piece survives the filters).
constexpr std::uint64_t kHullBytesPerPoint = 320;
// Tets per point, for the size of the output before it exists: 6.7 on uniform points,
// about 6.3 on shells and clusters, 6 on grids; 8 leaves room.
constexpr double kTetsPerPoint = 8;
// A frame's tets are 4 8-byte labels while they wait for the writer, and an
// encoder's scratch takes about 40 bytes a tet (io/tet_writer.hpp).
constexpr double kFrameBytesPerTet = 32, kEncoderBytesPerTet = 40;
// The smallest piece the hull filter works on (below it a piece's kernel is cheap).
constexpr std::size_t kMinHullPiece = 4096;
// The smallest sorted run (the reader's chunk).
constexpr std::size_t kMinRunPoints = std::size_t(1) << 16;

}  // namespace

MemoryBudget::MemoryBudget(std::uint64_t ceiling, std::uint64_t points, int threads, int cores)
    : ceiling_(ceiling),
      points_(points),
      threads_(std::max(1, threads)),
      cores_(std::max(1, cores)),
      frame_tets_(frame_tets_for(ceiling)) {
  // The reserve holds the process itself (the shared libraries' pages), the
  // allocator's slack and the folios that sequential scans map before they hand them
  // back (ReleaseBehind: two 4 MiB chunks a thread loading a window): a quarter of the
  // budget between 20 and 64 MiB, and the threads' chunks; at most 5/8 of the budget.
  // Smaller floors let small budgets overshoot (scripts/bench-memory checks the peaks).
  // The chunks: 8 MiB a thread, less at small budgets, whose windows' label ranges
  // are a few MiB of records at most (a 32nd of the budget a thread).
  const std::uint64_t chunks = std::min<std::uint64_t>(8 * kMiB, ceiling / 32) * std::uint64_t(threads_);
  runtime_ = std::min<std::uint64_t>(process_reserve(ceiling) + chunks, ceiling / 8 * 5);
}

std::uint64_t MemoryBudget::process_reserve(std::uint64_t ceiling) {
  return std::min<std::uint64_t>(std::clamp<std::uint64_t>(ceiling / 4, 20 * kMiB, 64 * kMiB), ceiling / 8 * 5);
}

void MemoryBudget::record(const std::string& phase, const std::string& name, std::uint64_t bytes) {
  for (Share& s : shares_)
    if (s.phase == phase && s.name == name) {
      s.bytes = bytes;
      return;
    }
  shares_.push_back({phase, name, bytes});
}

std::uint64_t MemoryBudget::phase_total(const std::string& phase) const {
  std::uint64_t total = 0;
  for (const Share& s : shares_)
    if (s.phase == phase) total += s.bytes;
  return total;
}

SortShares MemoryBudget::plan_sort() {
  // What the reserve leaves, in thirds: the run buffer, the merge, and (a quarter)
  // the hull pieces; each no larger than this input needs.
  const std::uint64_t avail = ceiling_ > runtime_ ? ceiling_ - runtime_ : 0;
  SortShares s;
  s.run_points = std::size_t(std::clamp<std::uint64_t>(avail / 3 / kRunBytesPerPoint, kMinRunPoints,
                                                       std::max<std::uint64_t>(points_, kMinRunPoints)));
  s.hull_piece_points = std::max<std::size_t>(
      kMinHullPiece,
      std::min<std::size_t>(std::size_t(avail / 4 / kHullBytesPerPoint / std::uint64_t(threads_)), s.run_points));
  // What a run of this input holds (the buffer is reserved for the points it will
  // hold, not the share), and the pieces at once: no more than a run has, and no more
  // than the quarter holds (many threads and a small budget: fewer than threads).
  const std::uint64_t run_used = std::min<std::uint64_t>(s.run_points, std::max<std::uint64_t>(points_, 1));
  const std::uint64_t piece_used = std::min<std::uint64_t>(s.hull_piece_points, run_used);
  const std::uint64_t piece_bytes = std::uint64_t(s.hull_piece_points) * kHullBytesPerPoint;
  const std::uint64_t pieces = (run_used + s.hull_piece_points - 1) / s.hull_piece_points;
  s.hull_threads = int(
      std::max<std::uint64_t>(1, std::min<std::uint64_t>({std::uint64_t(threads_), pieces, avail / 4 / piece_bytes})));
  // The merge needs no more than the runs hold (ExternalSorter caps each run's block
  // by the run's size): the whole input's records at most.
  s.merge_bytes = std::size_t(std::min<std::uint64_t>(avail / 3, std::max<std::uint64_t>(points_ * 32, kMiB)));
  record("sort", "runtime", runtime_);
  record("sort", "run_buffer", run_used * kRunBytesPerPoint);
  record("sort", "hull_pieces", piece_used * kHullBytesPerPoint * std::uint64_t(s.hull_threads));
  record("sort", "merge", s.merge_bytes);
  return s;
}

int MemoryBudget::encoders_for(std::uint64_t ceiling, int cores) {
  // As many as the machine has cores, whatever --threads (one encoder left a core idle
  // in every burst of a segment's tets), one per 256 MiB of budget (each holds about
  // three frames: 27 MiB at the largest), at most 16: on 16 cores 2 encoders could
  // not keep up with the insertion threads (issue 38: the writer busy 72 of 98 s).
  return std::clamp(std::min<int>(cores, int(std::min<std::uint64_t>(ceiling >> 28, 1 << 20))), 1, 16);
}

std::size_t MemoryBudget::frame_tets_for(std::uint64_t ceiling) {
  std::size_t tets = kSmallestFrameTets;
  while (tets < kFrameTets && 2 * tets <= ceiling / 1024) tets *= 2;
  return tets;
}

std::uint64_t MemoryBudget::writer_bytes_for(int encoders, std::uint64_t tets, std::size_t frame_tets) {
  // Frames alive: the one being filled, `encoders` queued and `encoders` being
  // compressed; no more than the output has, and none larger than the output.
  const double frame = double(std::min<std::uint64_t>(frame_tets, std::max<std::uint64_t>(tets, 1)));
  const double frames = std::min(2.0 * encoders + 1, std::ceil(double(tets) / double(frame_tets)) + 1);
  // An encoder's scratch is made when a frame first needs it (io::TetWriter): no more
  // of them than the output has frames.
  const double busy = std::min<double>(encoders, std::ceil(double(tets) / double(frame_tets)));
  return std::uint64_t((frames * kFrameBytesPerTet + busy * kEncoderBytesPerTet) * frame * 1.05);
}

KeepShares MemoryBudget::plan_keep(std::uint64_t map_bytes, std::uint64_t frame_bytes) {
  constexpr std::uint64_t kLeastSort = 4 * kMiB;
  const std::uint64_t fixed = runtime_ + map_bytes + frame_bytes;
  if (fixed + kLeastSort > ceiling_) {
    const std::uint64_t need = (fixed + kLeastSort + kMiB - 1) / kMiB;
    throw UsageError("--memory " + std::to_string(ceiling_ / kMiB) +
                     "M is too small for the keep step of this periodic job (its label map takes " +
                     std::to_string((map_bytes + kMiB - 1) / kMiB) + "M, its frames " +
                     std::to_string((frame_bytes + kMiB - 1) / kMiB) + "M): at least --memory " + std::to_string(need) +
                     "M");
  }
  KeepShares k{map_bytes, frame_bytes, std::min(ceiling_ - fixed, std::max(ceiling_ / 4, kLeastSort))};
  record("keep", "runtime", runtime_);
  record("keep", "label map", k.map_bytes);
  record("keep", "frames", k.frame_bytes);
  record("keep", "sort", k.sort_bytes);
  return k;
}

TriangulateShares MemoryBudget::plan_triangulate(std::uint64_t index_bytes, double windows_planned) {
  TriangulateShares t;
  t.encoders = encoders_for(ceiling_, cores_);
  // The output's write buffer: a 64th of the budget and no more than the output's
  // size (~50 bytes a point), from 64 KiB to 8 MiB (past which larger writes gained
  // nothing).
  t.file_buffer_bytes =
      std::size_t(std::clamp<std::uint64_t>(std::min(ceiling_ / 64, 64 * points_), 64 << 10, 8 * kMiB));
  t.writer_bytes = writer_bytes_for(t.encoders, std::uint64_t(kTetsPerPoint * double(points_)), frame_tets_) +
                   t.file_buffer_bytes + label_order_bytes_;
  t.index_bytes = index_bytes;
  // What the reserve and the writer leave: 75% for the windows (less the indexes),
  // 25% for the sorted file's pages that the queries map and the allocator's slack.
  // The query pages: an eighth of the budget (a smaller share makes the queries fault
  // the same regions in again and again), no more than the file and one 2 MiB region,
  // no more than that 25%. So the phase sums to at most the ceiling.
  const double fixed = double(runtime_) + double(t.writer_bytes);
  const double rest = std::max(0.0, double(ceiling_) - fixed);
  t.window_bytes = 0.75 * rest - double(index_bytes);
  // The shared rim tets (pipeline/window/shared_rim.hpp), out of the other 25%, never
  // out of the windows' (smaller windows made more zones, whose rims cost more queries
  // than the table saved: indoor 10^6 at 128M, 11 segments became 14). Up to an eighth
  // of what the reserve and the writer leave, and no more than 64 bytes a point (under
  // three 24-byte slots a point: the tets that cross zones are a fraction of the ~6.5 a point): what
  // the query pages leave of the 25%, and half of the query pages above 8 MiB. A 32nd
  // (still the least: a 32nd, out of the query pages above one region) was too small:
  // on `hills` 10^6 at 128M, 1.57 M rim tets were offered and 0.10 M found room, and the
  // zones after proved the rest again by their queries. Small budgets keep their query
  // pages: at 64M, taking 1.8 of their 6.6 MiB made `hills` 10% slower on two threads.
  const double room = 0.25 * rest;
  const double query_pages = std::min({double(ceiling_ / 8), double(points_) * 32 + 2.0 * kMiB, room});
  const double rim_cap = 64.0 * double(points_);
  const double rim_floor = std::clamp(query_pages - 2.0 * kMiB, 0.0, std::min(rest / 32, rim_cap));
  const double rim_spare = room - query_pages + std::max(0.0, query_pages - 8.0 * kMiB) / 2;
  const double rim = std::max(rim_floor, std::min({rest / 8, rim_cap, rim_spare}));
  t.shared_rim_bytes = std::uint64_t(rim);
  t.query_page_bytes = std::uint64_t(std::min(query_pages, room - rim));
  record("triangulate", "runtime", runtime_);
  record("triangulate", "writer", t.writer_bytes);
  record("triangulate", "query_pages", t.query_page_bytes);
  record("triangulate", "indexes", index_bytes);
  record("triangulate", "shared_rim", t.shared_rim_bytes);
  const double windows = windows_planned >= 0 ? std::min(windows_planned, t.window_bytes) : t.window_bytes;
  record("triangulate", "windows", windows > 0 ? std::uint64_t(windows) : 0);
  return t;
}

}  // namespace tetstream::pipeline
