#include "pipeline/periodic/keep.hpp"

#include "core/compiler.hpp"
#include "core/error.hpp"
#include "core/predicates.hpp"
#include "io/tet_container.hpp"
#include "io/tet_reader.hpp"
#include "io/tet_writer.hpp"
#include "pipeline/files/external_sort.hpp"
#include "pipeline/util/memory_budget.hpp"
#include "pipeline/periodic/keep_parts.hpp"
#include "pipeline/periodic/kept_stream.hpp"
#include "pipeline/periodic/tet_records.hpp"

#include <omp.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <exception>
#include <limits>
#include <ranges>
#include <stdexcept>

namespace tetstream::pipeline::periodic {

namespace {

constexpr std::uint64_t kNone = std::numeric_limits<std::uint64_t>::max();
constexpr std::size_t kChunk = std::size_t(1) << 16;

// What a label of the padded container is: its point's periodic label and its offset
// (bit k: -1 on axis k), in one word (periodic label << 4 | bits: one cache line a
// vertex instead of two, read at random).
struct PaddedMap {
  std::vector<std::uint64_t> code;
  std::vector<double> xyz;  // the padded points' coordinates (read once, not per tet)
  std::uint64_t points = 0;

  std::uint64_t plabel(std::uint64_t label) const { return code[label] >> 4; }
  std::uint64_t bits(std::uint64_t label) const { return code[label] & 15; }
};

// Pass 1 numbers the points (original index < N) in label order: the periodic labels
// keep the padded job's lexicographic order. Pass 2 maps every label, images too.
PaddedMap map_labels(const io::TetReader& r, const KeepInput& in) {
  const std::uint64_t n = r.point_count();
  std::vector<std::uint64_t> of_point(in.input_points, kNone);
  std::vector<std::uint64_t> ids(kChunk);
  PaddedMap m;
  for (std::uint64_t first = 0; first < n; first += kChunk) {
    const std::size_t k = std::size_t(std::min<std::uint64_t>(kChunk, n - first));
    r.read_points(first, k, nullptr, ids.data());
    for (std::size_t i = 0; i < k; ++i)
      if (ids[i] < in.input_points) of_point[ids[i]] = m.points++;
  }
  m.code.resize(n);
  m.xyz.resize(3 * n);
  for (std::uint64_t first = 0; first < n; first += kChunk) {
    const std::size_t k = std::size_t(std::min<std::uint64_t>(kChunk, n - first));
    r.read_points(first, k, &m.xyz[3 * first], ids.data());
    for (std::size_t i = 0; i < k; ++i) {
      std::uint64_t point = ids[i];
      std::uint8_t bits = 0;
      if (point >= in.input_points) {
        const std::uint64_t code = in.images->code.at(point - in.input_points);
        point = code >> 3;
        bits = std::uint8_t(code & 7);
      }
      if (of_point[point] == kNone) throw std::logic_error("periodic: an image without its point");
      m.code[first + i] = of_point[point] << 4 | bits;
    }
  }
  return m;
}

struct KeptFrame {
  std::vector<KeptTet> kept;
  std::uint64_t failures = 0, long_edges = 0;
};

// One frame of the padded container: every tet that may meet C (keep_parts.hpp) passes
// the completeness condition by its circumsphere, and those whose circumcentre lies in
// C are kept, in stored form. (The keep in the padded job, zone_keep.hpp, spares most
// of these spheres with its ball grid; this step after an MPI job computes them all.)
void keep_frame(const io::TetReader& r, std::uint64_t f, const PaddedMap& m, const KeepInput& in, const CentreBox& box,
                std::vector<std::uint64_t>& t, KeptFrame& out) {
  r.read_frame(f, t);
  out.kept.clear();
  out.failures = out.long_edges = 0;
  // The map's entries of a tet's vertices are read at random within the frame's slab of
  // labels (at 10^7 points some megabytes a thread, past the caches): each tet asks for
  // those of the tet kAhead places on, so that they arrive while this one is certified.
  constexpr std::size_t kAhead = 8;
  for (std::size_t i = 0; i < t.size(); i += 4) {
    for (std::size_t v = i + 4 * kAhead; v < std::min(t.size(), i + 4 * kAhead + 4); ++v) {
      TS_PREFETCH(&m.code[t[v]]);
      TS_PREFETCH(&m.xyz[3 * t[v]]);
    }
    const double* p[4];
    std::uint64_t label[4];
    int off[4][3];
    unsigned side[4];
    for (int j = 0; j < 4; ++j) {
      p[j] = &m.xyz[3 * t[i + j]];
      side[j] = centre_box_sides(p[j], box);
      label[j] = m.plabel(t[i + j]);
      for (int k = 0; k < 3; ++k) off[j][k] = -int(m.bits(t[i + j]) >> k & 1);
    }
    const core::Circumsphere s = core::circumsphere(p[0], p[1], p[2], p[3]);
    if (may_meet_centre_box(side) && !covers_centre_box(s, box)) {
      ++out.failures;
      continue;
    }
    if (!centre_in_box(s, p, box)) continue;
    KeptTet kt;
    if (!stored_form(label, off, kt)) {
      ++out.failures;
      continue;
    }
    out.long_edges += long_edge(p, in.period);
    out.kept.push_back(kt);
  }
  r.release_frame_pages(f);
}

// The smallest periodic label a kept tet of the frames still to come can have. Those
// frames hold tets whose padded labels are all at least `base` (the smallest base
// label among them), so every vertex lies at or past base's coordinate x_b on the sort
// axis (the padded labels are the lexicographic order, the sort axis first), and so
// does its point in the box (an image is its point minus a period or not moved on
// that axis). The periodic labels number the points in the same order: those before
// x_b are the F smallest, and no tet to come has a label below F.
class Frontier {
 public:
  Frontier(const PaddedMap& m, int axis) : m_(m), axis_(axis) {}

  // F for the points lying before coordinate x on the sort axis (non-decreasing x).
  std::uint64_t points_before(double x) {
    // The first padded label at or past x: the sort axis' coordinates never decrease.
    const auto labels = std::views::iota(cursor_, std::uint64_t(m_.code.size()));
    const auto first = std::ranges::partition_point(labels, [&](std::uint64_t l) { return coord(l) < x; });
    const std::uint64_t lo = cursor_ + std::uint64_t(first - labels.begin());
    for (; cursor_ < lo; ++cursor_) count_ += (m_.bits(cursor_) & 7) == 0;  // the box's own points
    return count_;
  }
  std::uint64_t before_label(std::uint64_t base) { return points_before(coord(base)); }

 private:
  double coord(std::uint64_t label) const { return m_.xyz[3 * label + std::uint64_t(axis_)]; }

  const PaddedMap& m_;
  int axis_;
  std::uint64_t cursor_ = 0, count_ = 0;
};

void write_points(const io::TetReader& r, const KeepInput& in, io::TetWriter& w) {
  std::vector<std::uint64_t> ids(kChunk), out_ids;
  std::vector<double> xyz(3 * kChunk), out_xyz;
  for (std::uint64_t first = 0; first < r.point_count(); first += kChunk) {
    const std::size_t k = std::size_t(std::min<std::uint64_t>(kChunk, r.point_count() - first));
    r.read_points(first, k, xyz.data(), ids.data());
    out_ids.clear();
    out_xyz.clear();
    for (std::size_t i = 0; i < k; ++i) {
      if (ids[i] >= in.input_points) continue;
      out_ids.push_back(ids[i]);
      out_xyz.insert(out_xyz.end(), &xyz[3 * i], &xyz[3 * i + 3]);
    }
    w.add_points(out_xyz.data(), out_ids.data(), out_ids.size());
  }
}

// The periodic points' bounding box (the container's header).
void points_bbox(const io::TetReader& r, const KeepInput& in, io::TetFileHeader& h) {
  std::vector<std::uint64_t> ids(kChunk);
  std::vector<double> xyz(3 * kChunk);
  for (int k = 0; k < 3; ++k) {
    h.bbox_min[k] = std::numeric_limits<double>::infinity();
    h.bbox_max[k] = -std::numeric_limits<double>::infinity();
  }
  for (std::uint64_t first = 0; first < r.point_count(); first += kChunk) {
    const std::size_t k = std::size_t(std::min<std::uint64_t>(kChunk, r.point_count() - first));
    r.read_points(first, k, xyz.data(), ids.data());
    for (std::size_t i = 0; i < k; ++i) {
      if (ids[i] >= in.input_points) continue;
      for (int a = 0; a < 3; ++a) {
        h.bbox_min[a] = std::min(h.bbox_min[a], xyz[3 * i + a]);
        h.bbox_max[a] = std::max(h.bbox_max[a], xyz[3 * i + a]);
      }
    }
  }
}

}  // namespace

KeepResult keep_periodic_tets(const KeepInput& in) {
  KeepResult res;
  const auto start = std::chrono::steady_clock::now();
  const auto since = [&start] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  const io::TetReader r(in.padded);
  // The ledger's keep phase: the label map (32 bytes a padded point, and 8 an input
  // point while it is built), each thread's decoded frame and kept tets (72 bytes a
  // tet) and the writer's batches (34 bytes a tet, and the encoded frame); the sort the rest.
  const int threads = std::max(1, in.threads);
  std::uint64_t frame_tets = 0;
  for (const auto& f : r.frames()) frame_tets = std::max<std::uint64_t>(frame_tets, f.tet_count);
  MemoryBudget budget(in.memory_bytes, r.point_count(), threads, threads);
  const KeepShares shares = budget.plan_keep(
      r.point_count() * (sizeof(std::uint64_t) + 3 * sizeof(double)) + in.input_points * sizeof(std::uint64_t),
      std::uint64_t(threads) * (frame_tets * 72 + in.frame_tets * 36));
  res.memory_shares = budget.shares();
  const PaddedMap m = map_labels(r, in);
  r.release_point_pages(0, r.point_count());  // read once into the map: their pages go back
  spdlog::debug("periodic keep: labels mapped in {:.2f}s", since());
  const CentreBox box = centre_box(in.period, in.margin);
  const int label_bits = std::max(1, int(std::bit_width(m.points)));

  // The writer first (the points come before the tets): a failing certificate
  // discards what it wrote.
  io::TetFileHeader h;
  h.point_count = m.points;
  h.input_count = in.input_points;
  h.coord_type = io::CoordType::kFloat64;
  h.tool = "tetstream 0.1.0";
  h.options = in.options_json;
  points_bbox(r, in, h);
  io::TetWriterOptions wo;
  wo.claim = in.claim;
  wo.threads = threads;
  io::TetWriter w(in.output, h, wo);
  write_points(r, in, w);
  r.release_point_pages(0, r.point_count());
  spdlog::debug("periodic keep: points written in {:.2f}s", since());
  w.add_section(io::kTagPeriodicBox, io::serialize_periodic_box(io::PeriodicBox{in.period, in.sort_axis}));

  // The sort's share: half for the tets waiting for the frontier, half for the
  // external sort of those written last.
  ExternalSorter<KeptTet, KeptTetLess> sorter(
      sort_options(std::size_t(shares.sort_bytes / 2), in.dir, "periodic-tets"));
  sorter.set_run_sort([label_bits](KeptTet* d, std::size_t n) { radix_sort_kept(d, n, label_bits); }, sizeof(KeptTet));
  io::PeriodicOffsetsWriter offsets;
  FrameFeeder feeder(
      [&w, &offsets](std::vector<std::uint64_t>& labels, std::vector<std::uint16_t>& codes) {
        w.add_tets(labels);
        offsets.add_frame(codes);
      },
      in.frame_tets);
  Frontier frontier(m, in.sort_axis);
  // The tets kept at an image of m across the sort axis' lower face (m's point within
  // the margin of the upper face) come first and are written last (keep_stage.cpp).
  const std::uint64_t deferred_from =
      Frontier(m, in.sort_axis)
          .points_before(in.period[std::size_t(in.sort_axis)] - in.margin[std::size_t(in.sort_axis)]);
  KeptStream stream([&feeder](std::span<const KeptTet> tets) { feeder.add(tets); }, deferred_from,
                    std::size_t(shares.sort_bytes / 2), sorter, label_bits);

  // Every thread certifies a frame and keeps its tets, then hands them to the stream
  // in the frames' order (an ordered region: the bytes do not depend on the threads),
  // while the others certify the next frames.
  const std::uint64_t frames = r.frame_count();
  std::vector<std::uint64_t> suffix_base(frames + 1, ~std::uint64_t(0));
  for (std::uint64_t f = frames; f-- > 0;) suffix_base[f] = std::min(suffix_base[f + 1], r.frames()[f].base_label);
  std::vector<KeptFrame> kept(static_cast<std::size_t>(threads));
  std::vector<std::vector<std::uint64_t>> decoded(static_cast<std::size_t>(threads));
  std::uint64_t failures = 0, long_edges = 0;
  // A failing ball (the margin doubles) or an error stops the pass: the frames left
  // are not certified. An exception leaves the region only as this pointer.
  std::atomic<bool> stop{false};
  std::exception_ptr error;
#pragma omp parallel for ordered schedule(dynamic, 1) num_threads(threads)
  for (std::uint64_t f = 0; f < frames; ++f) {
    const std::size_t me = std::size_t(omp_get_thread_num());
    std::exception_ptr frame_error;
    if (!stop.load(std::memory_order_relaxed)) {
      try {
        keep_frame(r, f, m, in, box, decoded[me], kept[me]);
      } catch (...) {
        frame_error = std::current_exception();
      }
    }
#pragma omp ordered
    {
      // Once stopped, every frame after is skipped here (its slot may hold an older frame's).
      if (!stop.load(std::memory_order_relaxed)) {
        try {
          if (frame_error) std::rethrow_exception(frame_error);
          failures += kept[me].failures;
          long_edges += kept[me].long_edges;
          if (failures != 0)
            stop.store(true);
          else
            stream.add(kept[me].kept, f + 1 < frames ? frontier.before_label(suffix_base[f + 1]) : m.points);
        } catch (...) {
          error = std::current_exception();
          stop.store(true);
        }
      }
    }
  }
  if (error) std::rethrow_exception(error);
  res.ball_failures = failures;
  res.points = m.points;
  spdlog::debug("periodic keep: frames certified in {:.2f}s", since());
  if (failures != 0) {
    w.discard();  // the next margin's writer starts the claimed file over
    return res;
  }
  if (long_edges != 0) throw long_edges_error(in.input, long_edges);
  stream.finish();
  feeder.flush();
  w.add_section(io::kTagPeriodicOffsets, offsets.payload());
  res.tets = feeder.count();
  w.finish();
  spdlog::debug("periodic keep: written in {:.2f}s", since());
  res.output_bytes = w.bytes_written();
  res.complete = true;
  return res;
}

}  // namespace tetstream::pipeline::periodic
