#include "pipeline/periodic/keep.hpp"

#include "core/error.hpp"
#include "core/predicates.hpp"
#include "io/tet_container.hpp"
#include "io/tet_reader.hpp"
#include "io/tet_writer.hpp"
#include "pipeline/files/external_sort.hpp"
#include "pipeline/util/memory_budget.hpp"
#include "pipeline/periodic/tet_records.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <limits>
#include <mutex>
#include <stdexcept>

namespace tetstream::pipeline::periodic {

namespace {

constexpr std::uint64_t kNone = std::numeric_limits<std::uint64_t>::max();
constexpr std::size_t kChunk = std::size_t(1) << 16;
constexpr std::uint8_t kCanonical = 8;  // PaddedMap::bits: the point's canonical image

// What a label of the padded container is: its point's periodic label and its offset
// (bit k: -1 on axis k), and whether it is the point's canonical image.
struct PaddedMap {
  std::vector<std::uint64_t> plabel;
  std::vector<std::uint8_t> bits;
  std::vector<double> xyz;  // the padded points' coordinates (read once, not per tet)
  std::uint64_t points = 0;
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
  m.plabel.resize(n);
  m.bits.resize(n);
  m.xyz.resize(3 * n);
  double threshold[3];  // a point at or past it on axis k has its canonical image at -1
  for (int k = 0; k < 3; ++k) threshold[k] = canonical_threshold(in.period[k], in.margin[k]);
  for (std::uint64_t first = 0; first < n; first += kChunk) {
    const std::size_t k = std::size_t(std::min<std::uint64_t>(kChunk, n - first));
    r.read_points(first, k, &m.xyz[3 * first], ids.data());
    const double* xyz = &m.xyz[3 * first];
    for (std::size_t i = 0; i < k; ++i) {
      std::uint64_t point = ids[i];
      std::uint8_t bits = 0;
      if (point >= in.input_points) {
        const std::uint64_t code = in.images->code.at(point - in.input_points);
        point = code >> 3;
        bits = std::uint8_t(code & 7);
      }
      if (of_point[point] == kNone) throw std::logic_error("periodic: an image without its point");
      bool canonical = true;
      for (int a = 0; a < 3; ++a) {
        const bool minus = bits >> a & 1;
        const double p = minus ? xyz[3 * i + a] + in.period[a] : xyz[3 * i + a];  // exact: the image was
        canonical = canonical && (minus == (p >= threshold[a]));
      }
      m.plabel[first + i] = of_point[point];
      m.bits[first + i] = std::uint8_t(bits | (canonical ? kCanonical : 0));
    }
  }
  return m;
}

// The circumball of a padded tet lies inside the padded box (-M, L)^3, with the
// circumsphere's proved error bounds and a relative slack for this test's own
// roundings: every periodic point it could hold is then in the padded set.
bool ball_inside(const double* p[4], const KeepInput& in, const double lower[3]) {
  const core::Circumsphere s = core::circumsphere(p[0], p[1], p[2], p[3]);
  if (!s.valid) return false;
  const double reach = (s.radius + s.radius_error + s.center_error) * (1 + 0x1p-40);
  for (int k = 0; k < 3; ++k) {
    const double slack = std::fabs(s.center[k]) * 0x1p-50 + 0x1p-1000;
    if (!(s.center[k] - reach - slack > lower[k]) || !(s.center[k] + reach + slack < in.period[k])) return false;
  }
  return std::isfinite(reach);
}

// CGAL's criterion for the 1-sheeted covering (Periodic_3_Delaunay_triangulation_3:
// every edge shorter than sqrt(0.166) times the period): an edge at or past it,
// conservatively, means this is not the triangulation CGAL defines in one sheet.
bool long_edge(const double* p[4], const KeepInput& in) {
  const double l = std::min({in.period[0], in.period[1], in.period[2]});
  const double limit = 0.166 * l * l * (1 - 0x1p-40);
  for (int i = 0; i < 4; ++i) {
    for (int j = i + 1; j < 4; ++j) {
      double d2 = 0;
      for (int k = 0; k < 3; ++k) d2 += (p[i][k] - p[j][k]) * (p[i][k] - p[j][k]);
      if (!(d2 < limit)) return true;
    }
  }
  return false;
}

struct FrameCounts {
  std::uint64_t failures = 0, long_edges = 0;
};

struct Sorters {
  ExternalSorter<KeptTet, KeptTetLess> tets;
  std::mutex mutex;
};

// One frame of the padded container: every tet with a vertex at its canonical image
// certified (its ball inside the padded box), and those whose smallest periodic label
// sits at its canonical image kept, in stored form.
FrameCounts keep_frame(const io::TetReader& r, std::uint64_t f, const PaddedMap& m, const KeepInput& in,
                       const double lower[3], Sorters& out) {
  std::vector<std::uint64_t> t;
  r.read_frame(f, t);
  std::vector<KeptTet> kept;
  FrameCounts counts;
  for (std::size_t i = 0; i < t.size(); i += 4) {
    int mi = 0;
    bool any = false;
    for (int j = 0; j < 4; ++j) {
      any = any || (m.bits[t[i + j]] & kCanonical);
      mi = m.plabel[t[i + j]] < m.plabel[t[i + mi]] ? j : mi;
    }
    if (!any) continue;
    const double* p[4];
    std::uint64_t label[4];
    int off[4][3];
    for (int j = 0; j < 4; ++j) {
      p[j] = &m.xyz[3 * t[i + j]];
      label[j] = m.plabel[t[i + j]];
      for (int k = 0; k < 3; ++k) off[j][k] = -int(m.bits[t[i + j]] >> k & 1);
    }
    if (!ball_inside(p, in, lower)) {
      ++counts.failures;
      continue;
    }
    if (!(m.bits[t[i + mi]] & kCanonical)) continue;
    KeptTet kt;
    if (!stored_form(label, off, kt)) {
      ++counts.failures;
      continue;
    }
    counts.long_edges += long_edge(p, in);
    kept.push_back(kt);
  }
  r.release_frame_pages(f);
  const std::lock_guard<std::mutex> lock(out.mutex);
  out.tets.push(std::span<const KeptTet>(kept));
  return counts;
}

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

// The kept tets in stored order, cut into frames at group boundaries, each frame's
// offsets beside it in POFS. Frames go to the writer `threads` at a time, encoded
// together (the same bytes as one at a time).
void write_tets(ExternalSorter<KeptTet, KeptTetLess>& tets, io::TetWriter& w, int threads, std::size_t frame_tets,
                std::uint64_t& count) {
  const std::size_t kFrame = frame_tets;
  std::vector<std::vector<std::uint64_t>> labels(1);
  std::vector<std::vector<std::uint16_t>> codes(1);
  io::PeriodicOffsetsWriter offsets;
  const auto flush = [&] {
    std::vector<std::span<const std::uint64_t>> batches(labels.begin(), labels.end());
    if (batches.back().empty()) batches.pop_back();
    w.add_tets(std::span<const std::span<const std::uint64_t>>(batches));
    for (const auto& c : codes) {
      if (c.empty()) continue;
      offsets.add_frame(c);
      count += c.size();
    }
    labels.assign(1, {});
    codes.assign(1, {});
  };
  const auto start = std::chrono::steady_clock::now();
  bool first = true;
  tets.merge([&](std::span<const KeptTet> batch) {
    if (first) {
      spdlog::debug("periodic keep: tets sorted in {:.2f}s",
                    std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
      first = false;
    }
    for (const KeptTet& t : batch) {
      if (codes.back().size() >= kFrame && t.v[0] != labels.back()[labels.back().size() - 4]) {
        if (int(codes.size()) >= std::max(1, threads))
          flush();
        else
          labels.emplace_back(), codes.emplace_back();
      }
      labels.back().insert(labels.back().end(), t.v, t.v + 4);
      codes.back().push_back(t.code);
    }
  });
  flush();
  const std::vector<std::uint8_t> payload = offsets.payload();
  w.add_section(io::kTagPeriodicOffsets, payload);
}

}  // namespace

KeepResult keep_periodic_tets(const KeepInput& in) {
  KeepResult res;
  const auto start = std::chrono::steady_clock::now();
  const auto since = [&start] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  const io::TetReader r(in.padded);
  // The ledger's keep phase: the label map (33 bytes a padded point, and 8 an input
  // point while it is built), each thread's decoded frame and kept tets (72 bytes a
  // tet) and the writer's batches (34 bytes a tet, and the encoded frame); the sort the rest.
  const int threads = std::max(1, in.threads);
  std::uint64_t frame_tets = 0;
  for (const auto& f : r.frames()) frame_tets = std::max<std::uint64_t>(frame_tets, f.tet_count);
  MemoryBudget budget(in.memory_bytes, r.point_count(), threads, threads);
  const KeepShares shares = budget.plan_keep(
      r.point_count() * (sizeof(std::uint64_t) + 1 + 3 * sizeof(double)) + in.input_points * sizeof(std::uint64_t),
      std::uint64_t(threads) * (frame_tets * 72 + in.frame_tets * 36));
  res.memory_shares = budget.shares();
  const PaddedMap m = map_labels(r, in);
  r.release_point_pages(0, r.point_count());  // read once into the map: their pages go back
  spdlog::debug("periodic keep: labels mapped in {:.2f}s", since());
  double lower[3];  // the padded box's lower corner, rounded up: -M, conservatively
  for (int k = 0; k < 3; ++k) {
    const double lo = (in.period[k] - in.margin[k]) - in.period[k];
    lower[k] = std::nextafter(std::nextafter(lo, 0.0), 0.0);
  }
  Sorters s{ExternalSorter<KeptTet, KeptTetLess>(sort_options(std::size_t(shares.sort_bytes), in.dir, "periodic-tets")),
            {}};
  const int label_bits = std::max(1, int(std::bit_width(m.points)));
  if (label_bits <= 32)
    s.tets.set_run_sort([label_bits](KeptTet* d, std::size_t n) { radix_sort_kept(d, n, label_bits); });
  std::uint64_t failures = 0, long_edges = 0;
  const std::int64_t frames = std::int64_t(r.frame_count());
#pragma omp parallel for schedule(dynamic, 1) num_threads(std::max(1, in.threads)) reduction(+ : failures, long_edges)
  for (std::int64_t f = 0; f < frames; ++f) {
    const FrameCounts c = keep_frame(r, std::uint64_t(f), m, in, lower, s);
    failures += c.failures;
    long_edges += c.long_edges;
  }
  res.ball_failures = failures;
  res.points = m.points;
  spdlog::debug("periodic keep: frames certified in {:.2f}s", since());
  if (failures != 0) return res;
  if (long_edges != 0) {
    throw InputError(in.input + ": " + std::to_string(long_edges) +
                     " Delaunay tets have an edge of sqrt(0.166) periods or longer: the 1-sheeted covering is not "
                     "a triangulation of the torus by CGAL's criterion (too few points for the box; "
                     "docs/periodic.md, \"When it refuses\")");
  }

  io::TetFileHeader h;
  h.point_count = m.points;
  h.input_count = in.input_points;
  h.coord_type = io::CoordType::kFloat64;
  h.tool = "tetstream 0.1.0";
  h.options = in.options_json;
  points_bbox(r, in, h);
  io::TetWriterOptions wo;
  wo.claim = in.claim;
  wo.threads = std::max(1, in.threads);
  io::TetWriter w(in.output, h, wo);
  write_points(r, in, w);
  r.release_point_pages(0, r.point_count());
  spdlog::debug("periodic keep: points written in {:.2f}s", since());
  io::PeriodicBox box{in.period, in.sort_axis};
  w.add_section(io::kTagPeriodicBox, io::serialize_periodic_box(box));
  write_tets(s.tets, w, in.threads, in.frame_tets, res.tets);
  w.finish();
  spdlog::debug("periodic keep: written in {:.2f}s", since());
  res.output_bytes = w.bytes_written();
  res.complete = true;
  return res;
}

}  // namespace tetstream::pipeline::periodic
