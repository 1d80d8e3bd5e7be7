// The public API (tetstream/tetstream.hpp) over the library's own pieces: the kernel
// (core::Delaunay), the job (pipeline::run_job) and the reader (io::TetReader).
#include "tetstream/tetstream.hpp"

#include "core/delaunay.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/run/run.hpp"

#include <omp.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <utility>

namespace tetstream {

Triangulation triangulate(std::span<const double> xyz, int threads) {
  if (xyz.size() % 3 != 0) throw UsageError("triangulate: the coordinates are not a multiple of 3");
  const std::size_t n = xyz.size() / 3;
  if (n > std::size_t(150'000'000))
    throw UsageError("triangulate: " + std::to_string(n) +
                     " points are more than the in-memory kernel holds; use run()");
  for (std::size_t i = 0; i < xyz.size(); ++i)
    if (!std::isfinite(xyz[i]))
      throw InputError("points: row " + std::to_string(i / 3) + ": a coordinate is not finite");
  core::Delaunay dt;
  if (dt.build(xyz.data(), nullptr, n) != core::BuildStatus::kOk)
    throw InputError("points: fewer than 4 affinely independent distinct points: no tetrahedron");
  // Of several copies of a point the kernel keeps whichever it inserted first; the
  // first in the caller's order names the vertex (as run() keeps the first).
  std::vector<std::uint32_t> name(n);
  std::vector<std::pair<std::uint32_t, std::uint32_t>> merged;
  for (std::size_t v = 0; v < n; ++v) name[v] = std::uint32_t(v);
  for (std::size_t v = 0; v < n; ++v)
    if (dt.incident_tet(core::VertexId(v)) == core::kNoTet) {
      core::VertexId to = dt.duplicate_of(core::VertexId(v));
      for (int guard = 0; guard < 64 && dt.incident_tet(to) == core::kNoTet && dt.duplicate_of(to) != to; ++guard)
        to = dt.duplicate_of(to);
      merged.emplace_back(std::uint32_t(v), std::uint32_t(to));
      name[to] = std::min(name[to], std::uint32_t(v));
    }
  const std::size_t slots = dt.num_tet_slots();
  constexpr std::int64_t kNone = -1;
  std::vector<std::int64_t> index(slots, kNone);
  std::int64_t m = 0;
  for (std::size_t t = 0; t < slots; ++t)
    if (dt.is_alive(core::TetId(t)) && !dt.is_infinite(core::TetId(t))) index[t] = m++;
  Triangulation out;
  out.simplices.resize(4 * std::size_t(m));
  out.neighbors.resize(4 * std::size_t(m));
  const int team = threads > 0 ? threads : omp_get_max_threads();
#pragma omp parallel for schedule(static) num_threads(team)
  for (std::size_t t = 0; t < slots; ++t) {
    const std::int64_t i = index[t];
    if (i == kNone) continue;
    for (int j = 0; j < 4; ++j) {
      out.simplices[4 * std::size_t(i) + j] = name[dt.vertex(core::TetId(t), j)];
      out.neighbors[4 * std::size_t(i) + j] = index[dt.neighbor(core::TetId(t), j) >> 2];
    }
  }
  std::vector<std::pair<std::int64_t, std::int64_t>> rows;
  for (const auto& [copy, vertex] : merged) {
    const std::uint32_t keep = name[vertex];
    if (copy != keep) rows.emplace_back(copy, keep);
    if (vertex != keep) rows.emplace_back(vertex, keep);
  }
  std::sort(rows.begin(), rows.end());
  rows.erase(std::unique(rows.begin(), rows.end()), rows.end());
  for (const auto& [i, j] : rows) out.duplicates.push_back(i), out.duplicates.push_back(j);
  return out;
}

RunSummary run(const RunOptions& options) {
  if (options.inputs.empty()) throw UsageError("run: no input");
  pipeline::RunOptions o;
  o.input = options.inputs.front();
  o.read.more_inputs.assign(options.inputs.begin() + 1, options.inputs.end());
  o.read.datasets = options.datasets;
  o.output = options.output;
  o.memory_bytes = options.memory_bytes;
  o.threads = options.threads;
  o.tmpdir = options.tmpdir;
  o.checkpoint = options.checkpoint;
  o.resume = options.resume;
  o.force = options.force;
  o.progress = options.progress;
  // Without progress, the job's info lines are held back for its duration (warnings and
  // errors still go to the program's spdlog logger).
  struct Level {
    spdlog::level::level_enum saved = spdlog::get_level();
    explicit Level(bool quiet) {
      if (quiet && saved < spdlog::level::warn) spdlog::set_level(spdlog::level::warn);
    }
    ~Level() { spdlog::set_level(saved); }
  } level(!options.progress);
  const pipeline::RunSummary s = pipeline::run_job(o);
  RunSummary r;
  r.input_points = s.input_points;
  r.points = s.points;
  r.duplicates = s.duplicates;
  r.tets = s.tets;
  r.segments = s.segments;
  r.zones = s.zones;
  r.output_bytes = s.output_bytes;
  r.seconds = s.seconds_total;
  r.resumed = s.resumed;
  return r;
}

struct Container::Impl {
  io::TetReader reader;
  explicit Impl(const std::string& path) : reader(path) {}
};

Container::Container(const std::string& path) : impl_(std::make_unique<Impl>(path)) {}
Container::~Container() = default;
Container::Container(Container&&) noexcept = default;
Container& Container::operator=(Container&&) noexcept = default;

std::uint64_t Container::point_count() const { return impl_->reader.point_count(); }
std::uint64_t Container::input_count() const { return impl_->reader.header().input_count; }
std::uint64_t Container::tet_count() const { return impl_->reader.tet_count(); }
std::uint64_t Container::frame_count() const { return impl_->reader.frame_count(); }

std::vector<double> Container::points(std::uint64_t first, std::uint64_t count) const {
  const io::TetReader& r = impl_->reader;
  first = std::min(first, r.point_count());
  count = std::min(count, r.point_count() - first);
  std::vector<double> xyz(3 * count);
  r.read_points(first, std::size_t(count), xyz.data(), nullptr);
  return xyz;
}

std::vector<std::uint64_t> Container::original_ids(std::uint64_t first, std::uint64_t count) const {
  const io::TetReader& r = impl_->reader;
  first = std::min(first, r.point_count());
  count = std::min(count, r.point_count() - first);
  std::vector<std::uint64_t> ids(count);
  r.read_points(first, std::size_t(count), nullptr, ids.data());
  return ids;
}

std::vector<std::uint64_t> Container::frame(std::uint64_t k, bool original_ids) const {
  const io::TetReader& r = impl_->reader;
  if (k >= r.frame_count()) throw UsageError("frame " + std::to_string(k) + " out of range");
  std::vector<std::uint64_t> labels;
  r.read_frame(k, labels);
  if (original_ids) r.map_to_original(labels);
  return labels;
}

}  // namespace tetstream
