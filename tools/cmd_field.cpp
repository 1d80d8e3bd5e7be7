// `tetstream field`: per-point fields from a .tets container, out of core
// (pipeline/field.hpp, docs/fields.md).
#include "core/error.hpp"
#include "pipeline/field/field.hpp"
#include "pipeline/util/progress.hpp"
#include "pipeline/run/run.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/periodic/field.hpp"
#include "tools/command.hpp"

#include <spdlog/spdlog.h>

#include <iostream>
#include <memory>

namespace tetstream::cli {
namespace {

constexpr const char* kFieldHelp =
    "Outputs (.npy, one entry per point in the input's order; exact duplicates merged by\n"
    "`run` have no entry of their own):\n"
    "  --density dtfe     PREFIX.density.npy   rho_i = 4 m_i / (sum of the volumes of the tets at i)\n"
    "  --voronoi-volume   PREFIX.voronoi.npy   the Voronoi cell's volume; +inf on the hull\n"
    "  --neighbours       PREFIX.neighbours.offsets.npy, PREFIX.neighbours.indices.npy (CSR; int32\n"
    "                     when every offset and index fits, else int64; --index-dtype int64: always)\n"
    "  --grid N|NX,NY,NZ  PREFIX.grid.npy      the DTFE density at the cell centres, shape (NX, NY, NZ);\n"
    "                                          NaN outside the hull\n"
    "Hull points: density NaN with --hull nan (default), the open-star estimate with --hull open\n"
    "(the same formula over the incomplete star; the linear field then integrates to the total\n"
    "mass). See docs/fields.md.";

struct FieldArgs {
  pipeline::FieldOptions options;
  std::string memory = "1G", density, grid, box, hull = "nan", dtype = "float64", index_dtype = "auto";
};

// -o is a prefix for several files; a user who names one (f.npy, f.density.npy) means
// the prefix before it: f.density.npy, never f.npy.density.npy.
std::string field_prefix(std::string out) {
  const auto strip = [&out](const std::string& suffix) {
    if (out.size() > suffix.size() && out.compare(out.size() - suffix.size(), suffix.size(), suffix) == 0) {
      out.resize(out.size() - suffix.size());
      return true;
    }
    return false;
  };
  if (strip(".npy"))
    for (const char* what : {".density", ".voronoi", ".grid", ".neighbours.offsets", ".neighbours.indices"})
      if (strip(what)) break;
  return out;
}

// A periodic container (docs/periodic.md, "Fields"): no hull, the grid over the box.
void run_field_periodic(const FieldArgs& args, Context& ctx) {
  const auto& o = args.options;
  if (o.neighbours || !o.mass.empty() || o.has_box || args.hull != "nan")
    throw UsageError("field: a periodic container takes --density, --voronoi-volume, --grid and --dtype only (yet)");
  pipeline::periodic::PeriodicFieldOptions p;
  p.prefix = o.output;
  p.density = o.density;
  p.voronoi = o.voronoi;
  p.grid = o.grid;
  p.float32 = o.dtype == pipeline::FieldType::kFloat32;
  if (!p.density && !p.voronoi && p.grid[0] == 0)
    throw UsageError("field: ask for at least one output (--density dtfe, --voronoi-volume, --grid N)");
  const auto s = pipeline::periodic::periodic_field(o.input, p);
  spdlog::info("periodic: {} points, {} tets; sum rho W / 4 = {:.17g}, Voronoi volumes sum to {:.17g}", s.points,
               s.tets, s.mass_check, s.voronoi_sum);
  ctx.summary = {{"command", "field"},
                 {"input", o.input},
                 {"periodic", true},
                 {"files", s.files},
                 {"points", s.points},
                 {"tets", s.tets},
                 {"nan_points", s.nan_points},
                 {"nan_cells", s.nan_cells},
                 {"mass_check", s.mass_check},
                 {"voronoi_sum", s.voronoi_sum},
                 {"star_volume_sum", s.star_sum}};
  if (!ctx.global.json)
    for (const auto& f : s.files) std::cout << f << "\n";
}

void run_field(FieldArgs& args, Context& ctx) {
  auto& o = args.options;
  o.output = field_prefix(o.output);
  o.memory_bytes = pipeline::parse_memory_size(args.memory);
  o.progress = !ctx.global.quiet;
  if (!args.density.empty() && args.density != "dtfe")
    throw UsageError("field: --density: unknown estimator '" + args.density + "' (dtfe)");
  o.density = !args.density.empty();
  if (!args.grid.empty()) o.grid = pipeline::parse_grid(args.grid);
  if (!args.box.empty()) o.box = pipeline::parse_box(args.box), o.has_box = true;
  if (args.hull != "nan" && args.hull != "open")
    throw UsageError("field: --hull must be nan or open, not '" + args.hull + "'");
  o.hull = args.hull == "open" ? pipeline::HullMode::kOpen : pipeline::HullMode::kNan;
  if (args.dtype != "float64" && args.dtype != "float32" && args.dtype != "f8" && args.dtype != "f4")
    throw UsageError("field: --dtype must be float32 or float64, not '" + args.dtype + "'");
  o.dtype =
      args.dtype == "float32" || args.dtype == "f4" ? pipeline::FieldType::kFloat32 : pipeline::FieldType::kFloat64;
  if (args.index_dtype != "auto" && args.index_dtype != "int64")
    throw UsageError("field: --index-dtype must be auto or int64, not '" + args.index_dtype + "'");
  o.neighbour_int64 = args.index_dtype == "int64";
  if (io::TetReader::is_periodic_file(o.input)) {
    run_field_periodic(args, ctx);
    return;
  }
  const pipeline::FieldSummary s = pipeline::compute_fields(o);
  nlohmann::json files = nlohmann::json::object();
  for (const auto& f : s.files) files[f.what] = f.path;
  spdlog::info("{} points ({} on the hull), {} tets in {} batches (window {} labels) in {:.2f}s", s.points,
               s.hull_points, s.tets, s.batches, s.window_labels, s.seconds);
  for (const auto& f : s.files) spdlog::info("wrote {}", f.path);
  ctx.summary = {
      {"command", "field"},
      {"input", o.input},
      {"files", files},
      {"points", s.points},
      {"hull_points", s.hull_points},
      {"tets", s.tets},
      {"frames", s.frames},
      {"batches", s.batches},
      {"window_labels", s.window_labels},
      {"ring_labels", s.ring_labels},
      {"far_labels_peak", s.far_labels_peak},
      {"hull_volume", s.tet_volume},
      {"interior_voronoi_volume", s.interior_voronoi},
      {"voronoi_total_with_hull_pieces", s.voronoi_total},
      {"total_mass", s.total_mass},
      {"neighbour_entries", s.neighbour_entries},
      {"neighbour_dtype", s.neighbour_dtype.empty() ? nlohmann::json(nullptr) : nlohmann::json(s.neighbour_dtype)},
      {"grid_points", s.grid_points},
      {"grid_inside", s.grid_inside},
      {"hull", args.hull},
      {"dtype", o.dtype == pipeline::FieldType::kFloat32 ? "float32" : "float64"},
      {"memory_planned", s.memory_planned},
      {"seconds", s.seconds}};
  if (!ctx.global.json)
    for (const auto& f : s.files) std::cout << f.path << "\n";
}

void setup_field(CLI::App& app, Context& ctx) {
  auto args = std::make_shared<FieldArgs>();
  CLI::App* cmd = app.add_subcommand(
      "field", "Per-point fields from a .tets container: DTFE density, Voronoi volumes, neighbours, grids");
  cmd->footer(kFieldHelp);
  cmd->add_option("input", args->options.input, "The container (.tets)")->required();
  cmd->add_option("-o,--output", args->options.output,
                  "Output prefix: writes PREFIX.density.npy, ... (a trailing .npy, or .density.npy etc., is dropped)")
      ->required();
  cmd->add_option("--density", args->density, "Per-point density estimator: dtfe");
  cmd->add_flag("--voronoi-volume", args->options.voronoi, "Per-point Voronoi cell volume");
  cmd->add_flag("--neighbours,--neighbors", args->options.neighbours, "Delaunay neighbours of each point (CSR)");
  cmd->add_option("--grid", args->grid, "DTFE density on a grid of N^3 or NX,NY,NZ cells (values at the centres)");
  cmd->add_option("--box", args->box,
                  "The grid's box xmin,ymin,zmin,xmax,ymax,zmax (default: the points' bounding box)");
  cmd->add_option("--hull", args->hull, "Density at hull points: nan or open")->capture_default_str();
  cmd->add_option("--mass", args->options.mass,
                  "Per-point masses in input order (.npy float64/float32, or raw float64)");
  cmd->add_option("--dtype", args->dtype, "float64 or float32 (density, Voronoi volume, grid)")->capture_default_str();
  cmd->add_option("--index-dtype", args->index_dtype,
                  "The neighbour arrays: auto (int32 when every offset and index fits, else int64) or int64")
      ->capture_default_str();
  cmd->add_option("--memory", args->memory, "Memory budget, e.g. 512M, 4G")->capture_default_str();
  cmd->add_option("--tmpdir", args->options.tmpdir,
                  "Directory for temporary files (default: $TMPDIR, else the output's)");
  cmd->callback([args, &ctx] { run_field(*args, ctx); });
}

}  // namespace
TETSTREAM_COMMAND(55, setup_field);
}  // namespace tetstream::cli
