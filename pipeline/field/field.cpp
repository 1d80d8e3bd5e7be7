#include "pipeline/field/field.hpp"

#include "core/error.hpp"
#include "io/npy.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/files/external_sort.hpp"
#include "pipeline/field/accumulate.hpp"
#include "pipeline/field/grid.hpp"
#include "pipeline/field/neighbours.hpp"
#include "pipeline/field/output.hpp"
#include "pipeline/field/window.hpp"
#include "pipeline/util/progress.hpp"
#include "pipeline/files/temp_files.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <sstream>

namespace tetstream::pipeline {

void FieldOptions::validate() const {
  if (input.empty()) throw UsageError("field: no input container given");
  if (output.empty()) throw UsageError("field: no output given (-o PREFIX)");
  if (!density && !voronoi && !neighbours && !grid_wanted())
    throw UsageError("field: nothing to compute: give --density dtfe, --voronoi-volume, --neighbours or --grid N");
  if (grid_wanted() && (grid[0] == 0 || grid[1] == 0 || grid[2] == 0))
    throw UsageError("field: --grid sizes must be >= 1");
  if (grid_wanted() && grid[0] * grid[1] > (std::uint64_t(1) << 40) / std::max<std::uint64_t>(grid[2], 1))
    throw UsageError("field: --grid has too many points");
  if (has_box)
    for (int k = 0; k < 3; ++k)
      if (!(box[std::size_t(k)] < box[std::size_t(k + 3)]) || !std::isfinite(box[std::size_t(k)]) ||
          !std::isfinite(box[std::size_t(k + 3)]))
        throw UsageError("field: --box needs finite xmin < xmax, ymin < ymax, zmin < zmax");
  if (memory_bytes < (std::uint64_t(64) << 20)) throw UsageError("field: --memory must be at least 64M");
}

namespace {

std::vector<std::string> split(const std::string& text) {
  std::vector<std::string> parts;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) parts.push_back(item);
  return parts;
}

double parse_double(const std::string& s, const std::string& what) {
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (s.empty() || end != s.c_str() + s.size() || !std::isfinite(v))
    throw UsageError("field: " + what + ": '" + s + "' is not a finite number");
  return v;
}

// Memory plan (bytes per item, measured on the structures the passes hold):
//   per window label: coordinates 24, original index 8, sums 24 (+ density 8 in the
//     grid pass);
//   per batch tet: labels 32, contributions 72, with neighbours 6 packed edges of 8,
//     the directed entries, and the radix sorts' other buffers;
// and the external sorts of the outputs their share. The ring is a power of two.
constexpr std::uint64_t kReserve = std::uint64_t(40) << 20;  // code, decoders, I/O buffers
std::uint64_t label_bytes(const FieldOptions&) { return 64; }
// With neighbours: 6 packed edges and their radix buffer (96), the batch's entries,
// about 3 a tet after the batch's de-duplication, and their radix buffer (96 when an
// entry was 16 bytes; 8 since session 32), and the rows cut from them plus their
// starts and lengths (32 with 8-byte entries; 4 now). The 224 are kept as a bound.
// The neighbours alone keep a volume a tet (8) instead of the contributions (72).
bool volumes_only(const FieldOptions& o) { return o.neighbours && !o.density && !o.voronoi && !o.grid_wanted(); }
std::uint64_t tet_bytes(const FieldOptions& o) { return (volumes_only(o) ? 40 : 104) + (o.neighbours ? 224 : 0); }

std::string default_tmpdir(const FieldOptions& o) {
  if (!o.tmpdir.empty()) return o.tmpdir;
  if (const char* t = std::getenv("TMPDIR"); t && *t) return t;
  const std::filesystem::path p = std::filesystem::path(o.output).parent_path();
  return p.empty() ? "." : p.string();
}

}  // namespace

std::array<std::uint64_t, 3> parse_grid(const std::string& text) {
  const std::vector<std::string> parts = split(text);
  if (parts.size() != 1 && parts.size() != 3) throw UsageError("field: --grid wants N or NX,NY,NZ, not '" + text + "'");
  std::array<std::uint64_t, 3> g{};
  for (std::size_t k = 0; k < 3; ++k) {
    const std::string& s = parts[parts.size() == 1 ? 0 : k];
    char* end = nullptr;
    const unsigned long long v = std::strtoull(s.c_str(), &end, 10);
    if (s.empty() || end != s.c_str() + s.size() || v == 0 || v > (1u << 20) || s[0] == '-')
      throw UsageError("field: --grid: '" + s + "' is not a size in 1..1048576");
    g[k] = v;
  }
  return g;
}

std::array<double, 6> parse_box(const std::string& text) {
  const std::vector<std::string> parts = split(text);
  if (parts.size() != 6) throw UsageError("field: --box wants xmin,ymin,zmin,xmax,ymax,zmax, not '" + text + "'");
  std::array<double, 6> b{};
  for (std::size_t k = 0; k < 6; ++k) b[k] = parse_double(parts[k], "--box");
  return b;
}

namespace {

// The memory plan of a field job: the window of labels and the batches of tets
// within their caps, and what is left for the output sorts.
struct FieldPlan {
  BatchPlan batches;
  std::uint64_t window_bytes = 0, batch_bytes = 0, sort_bytes = 0;
};

FieldPlan plan_field_memory(const FieldOptions& options, const io::TetReader& reader, FieldSummary& summary) {
  const io::TetFileHeader& h = reader.header();
  const std::uint64_t n = reader.point_count();
  FieldPlan fp;
  // Budget caps: window 40%, batch 25%; the output sorts get the rest (split between them).
  const std::uint64_t usable = options.memory_bytes - kReserve;
  const std::uint64_t window_bytes = fp.window_bytes = usable / 100 * 40,
                      batch_bytes = fp.batch_bytes = usable / 100 * 25;
  std::uint64_t max_labels =
      std::min<std::uint64_t>(std::bit_floor(window_bytes / label_bytes(options)), std::uint64_t(1) << 32);
  const std::uint64_t budget_tets = std::max<std::uint64_t>(batch_bytes / tet_bytes(options), 1);
  std::uint64_t max_tets = budget_tets;
  // Scratch reused, not re-faulted; at most 2^20 tets (the neighbours may take more,
  // below): fewer batches are fewer parallel regions (on a loaded machine an idle
  // OpenMP thread spins through every serial step between them), fewer merges of the
  // pending entries, and several frames a batch to decode in parallel (`run`'s frames
  // hold a little over 2^18 tets, so smaller batches are mostly one frame, decoded by
  // one thread while the others wait). Larger batches cost resident memory.
  max_tets = std::min<std::uint64_t>(max_tets, std::uint64_t(1) << 20);
  if (options.batch_tets) max_tets = options.batch_tets;
  if (options.ring_labels) {
    if (!std::has_single_bit(options.ring_labels)) throw UsageError("field: ring_labels must be a power of two");
    max_labels = options.ring_labels;
  }
  // Edges and entries are packed in 64 bits: labels and original indices below 2^32.
  if (options.neighbours && std::max(n, h.input_count) > (std::uint64_t(1) << 32))
    throw UsageError("field: --neighbours handles up to 2^32 points");
  BatchPlan& plan = fp.batches;
  plan = plan_batches(reader.frames(), n, max_tets, max_labels, options.input);
  // With neighbours, the entries of the unretired labels (about 16 a window label) are
  // carried from batch to batch (merged with each batch's, field_accumulate.cpp):
  // batches of 2^20 tets, whose new entries are fewer than those, spend most of that
  // work on old ones. Larger batches, as the budget allows, keep the new entries the
  // larger part.
  if (options.neighbours && !options.batch_tets) {
    const std::uint64_t wanted = std::min(std::bit_ceil(16 * plan.window_labels), budget_tets);
    if (wanted > max_tets) plan = plan_batches(reader.frames(), n, max_tets = wanted, max_labels, options.input);
  }
  summary.batches = plan.batches.size();
  summary.window_labels = plan.window_labels;
  summary.ring_labels = plan.ring_labels;
  // The output sorts take what the window and the batches leave (at least 20%): the
  // window is usually far below its cap, and a sort that fits in memory never spills.
  // With neighbours, the entries of the window's unretired labels stay pending from
  // batch to batch: about 16 of 8 bytes a label, in two buffers (the merge writes the
  // next batch's into the other); 512 bytes a label bound them with room to spare.
  const std::uint64_t held = plan.ring_labels * label_bytes(options) + plan.largest_batch_tets * tet_bytes(options) +
                             (options.neighbours ? plan.window_labels * 512 : 0);
  const std::uint64_t sort_bytes = fp.sort_bytes = std::max(usable / 5, usable > held ? usable - held : 0);
  summary.memory_planned = kReserve + held + sort_bytes;
  spdlog::info("field: {} points, {} tets in {} frames, {} batches; window {} labels (ring {}), planned {}", n,
               summary.tets, summary.frames, summary.batches, plan.window_labels, plan.ring_labels,
               human_bytes(double(summary.memory_planned)));
  return fp;
}

// The neighbour rows as the CSR pair of files.
void write_neighbours(NeighbourRows& neighbours, const FieldOptions& options, FieldSummary& summary) {
  // int32 when it holds every offset and index (scipy.sparse makes the same choice),
  // known only now that the entries are counted.
  const bool wide = options.neighbour_int64 || neighbours.needs_int64();
  neighbours.write(field_path(options, "neighbours.offsets"), field_path(options, "neighbours.indices"), wide);
  summary.neighbour_entries = neighbours.entries();
  summary.neighbour_dtype = wide ? "int64" : "int32";
  spdlog::info("field: {} neighbour entries in {} bucket(s){}", neighbours.entries(), neighbours.buckets(),
               neighbours.spilled() ? ", spilled to disk" : "");
  summary.files.push_back({"neighbours.offsets", field_path(options, "neighbours.offsets")});
  summary.files.push_back({"neighbours.indices", field_path(options, "neighbours.indices")});
}

// The density sampled on the grid, from the densities by label in rho_path.
void write_grid(const io::TetReader& reader, const BatchPlan& plan, const FieldOptions& options,
                const std::string& rho_path, std::uint64_t memory_bytes, const std::string& tmpdir, Progress* progress,
                FieldSummary& summary) {
  const io::TetFileHeader& h = reader.header();
  GridSpec g;
  g.n = options.grid;
  for (std::size_t k = 0; k < 3; ++k) {
    g.lo[k] = options.has_box ? options.box[k] : h.bbox_min[k];
    g.hi[k] = options.has_box ? options.box[k + 3] : h.bbox_max[k];
    if (!(g.hi[k] > g.lo[k]))
      throw UsageError("field: the points are flat along axis " + std::to_string(k) + ": give --box");
  }
  const double ext[3] = {h.bbox_max[0] - h.bbox_min[0], h.bbox_max[1] - h.bbox_min[1], h.bbox_max[2] - h.bbox_min[2]};
  const int axis = int(std::max_element(ext, ext + 3) - ext);  // the sort axis of `run` (point_sort.cpp)
  const GridStats gs = sample_grid(reader, plan, g, axis, rho_path, options, memory_bytes, tmpdir, progress);
  summary.grid_points = g.n[0] * g.n[1] * g.n[2];
  summary.grid_inside = gs.inside;
  summary.files.push_back({"grid", options.output + ".grid.npy"});
}

}  // namespace

FieldSummary compute_fields(const FieldOptions& options) {
  options.validate();
  const auto t0 = std::chrono::steady_clock::now();
  const io::TetReader reader(options.input);
  // Every field is computed from the points' coordinates: a damaged points section
  // would give other numbers with no error, so it is checked before any work (the
  // frames are checked one by one as they are decoded).
  reader.verify_points();
  const io::TetFileHeader& h = reader.header();
  const std::uint64_t n = reader.point_count();
  FieldSummary summary;
  summary.points = n;
  summary.tets = reader.tet_count();
  summary.frames = reader.frame_count();

  const FieldPlan fp = plan_field_memory(options, reader, summary);
  const BatchPlan& plan = fp.batches;
  const std::uint64_t window_bytes = fp.window_bytes, batch_bytes = fp.batch_bytes, sort_bytes = fp.sort_bytes;

  // The mass file is checked (length, format) before any work; its values when read.
  std::unique_ptr<io::ScalarFileReader> masses;
  if (!options.mass.empty())
    masses = std::make_unique<io::ScalarFileReader>(options.mass, h.input_count ? h.input_count : n);
  TempDir tmp(default_tmpdir(options), "tetstream-field");
  const bool grid = options.grid_wanted();
  const bool need_points = options.density || options.voronoi || (grid && !options.mass.empty());
  const std::uint64_t sorts = std::uint64_t(need_points) + std::uint64_t(options.neighbours);
  auto sort_options = [&](const char* name) {
    ExternalSortOptions so;
    so.memory_bytes = std::max<std::uint64_t>(sort_bytes / std::max<std::uint64_t>(sorts, 1), 8 << 20);
    so.dir = tmp.dir();
    so.name = name;
    return so;
  };
  std::unique_ptr<PointOrder> points;
  std::unique_ptr<NeighbourRows> neighbours;
  if (need_points) {
    const ExternalSortOptions so = sort_options("points");
    points = std::make_unique<PointOrder>(options, std::max(h.input_count, n),
                                          options.point_memory ? options.point_memory : so.memory_bytes, so);
  }
  if (options.neighbours) {
    // Entries = twice the edges; a triangulated ball has V + T + F_hull / 2 - 1 edges
    // and F_hull <= 2 V, so 2 (2 N + T) bounds them (it only plans the buckets).
    const std::uint64_t bound = 2 * (2 * n + summary.tets);
    const std::uint64_t share =
        options.neighbour_memory ? options.neighbour_memory : sort_options("neighbours").memory_bytes;
    neighbours =
        std::make_unique<NeighbourRows>(std::max(h.input_count, n), n, bound, share, tmp.path("neighbour-rows.u32"));
  }
  const std::string rho_path = tmp.path("rho-by-label.f64");
  std::unique_ptr<BinaryFile> rho_file;
  if (grid && options.mass.empty()) rho_file = std::make_unique<BinaryFile>(rho_path, "wb");

  Progress progress("field", "tets", summary.tets * (grid ? 2 : 1), options.progress);
  double volume4 = 0.0;
  AccumulateSinks sinks;
  sinks.voronoi = options.voronoi;
  // The hull flag matters to the files of the density and the grid; alone, the
  // neighbours need it only for `hull_points`, which the rows give without hull terms.
  sinks.hull_terms = !volumes_only(options);
  sinks.points = [&](std::span<const FinalPoint> retired) {
    for (const FinalPoint& p : retired) {
      volume4 += p.volume;
      summary.hull_points += p.hull;
      if (!p.hull) summary.interior_voronoi += p.voronoi;
      summary.voronoi_total += p.voronoi;
      if (rho_file) {
        const double rho = dtfe_density(1.0, p.volume, p.hull, options.hull);
        rho_file->write(&rho, sizeof rho, 1);
      }
    }
    if (points) points->add(retired);
  };
  if (neighbours)  // every point gets a row, even one in no edge (not in a valid container)
    sinks.row = [&](std::uint64_t original, std::span<const std::uint32_t> row) { neighbours->add(original, row); };
  const AccumulateStats acc = accumulate_fields(reader, plan, sinks, &progress);
  summary.tet_volume = volume4 / 4.0;
  summary.far_labels_peak = acc.peak_far;
  if (neighbours)
    spdlog::debug("field: {} edge keys sorted, {} unique in their batches", acc.batch_edge_keys, acc.batch_edges);

  if (points) {
    spdlog::debug("field: points {} by original index", points->placed() ? "placed" : "sorted");
    // With masses, the grid's densities come back to label order through another sort.
    std::unique_ptr<ExternalSorter<GridDensity, ByLabel>> by_label;
    std::function<void(std::uint64_t, double)> sink;
    if (grid && masses) {
      by_label = std::make_unique<ExternalSorter<GridDensity, ByLabel>>(sort_options("rho"));
      sink = [&](std::uint64_t label, double rho) { by_label->push({label, rho}); };
    }
    write_point_fields(*points, options, n, masses.get(), sink, summary);
    points.reset();
    if (by_label) {
      rho_file = std::make_unique<BinaryFile>(rho_path, "wb");
      by_label->merge([&](std::span<const GridDensity> batch) {
        for (const GridDensity& d : batch) rho_file->write(&d.rho, sizeof d.rho, 1);
      });
    }
  } else {
    summary.total_mass = double(n);
  }
  if (neighbours) {
    write_neighbours(*neighbours, options, summary);
    neighbours.reset();
  }
  if (grid) {
    rho_file->close();
    rho_file.reset();
    write_grid(reader, plan, options, rho_path, window_bytes + batch_bytes / 2, tmp.dir(), &progress, summary);
  }
  progress.finish();
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return summary;
}

}  // namespace tetstream::pipeline
