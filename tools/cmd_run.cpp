// `tetstream run`: triangulate a point file out of core into a .tets container.
#include "core/error.hpp"
#include "io/mesh_export.hpp"
#include "io/point_format.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/util/progress.hpp"
#include "pipeline/run/run.hpp"
#include "pipeline/distributed/run_distributed.hpp"
#include "pipeline/periodic/periodic.hpp"
#include "pipeline/run/summary_json.hpp"
#include "tools/command.hpp"
#include "tools/point_options.hpp"
#include "tools/world.hpp"

#include <spdlog/spdlog.h>

#include <filesystem>
#include <optional>

namespace tetstream::cli {
namespace {

struct RunArgs {
  pipeline::RunOptions options;
  std::string memory = "1G";
  std::string periodic;  // --periodic: L, Lx,Ly,Lz or auto; empty: not periodic
  std::string outside = "wrap";
  double margin = 0;           // 0: the default first margin (PeriodicOptions)
  std::string index = "auto";  // --index
  std::string labels;          // --labels; empty: bricks, sorted with --periodic
};

// `run --periodic`: the triangulation of the flat torus (docs/periodic.md).
void run_periodic(RunArgs& args, Context& ctx) {
  auto& o = args.options;
  pipeline::periodic::PeriodicOptions p;
  p.period = pipeline::periodic::parse_period(args.periodic, o.input);
  p.wrap = args.outside == "wrap";
  if (args.margin > 0) p.margin_spacings = args.margin, p.margin_from_density = false;
  // Under mpirun every rank runs the padded job (the same bytes); rank 0 reports.
  pipeline::Communicator& comm = world();
  const auto s = pipeline::periodic::run_periodic(o, p, comm);
  if (comm.rank() != 0) return;
  spdlog::info(
      "periodic box {} x {} x {}: {} points ({} wrapped, {} images at margin {:.4g}) -> {} tets in {:.2f}s "
      "({} attempt{}{})",
      p.period[0], p.period[1], p.period[2], s.points, s.wrapped, s.images, s.margin[0], s.tets, s.seconds_total,
      s.attempts, s.attempts == 1 ? "" : "s", s.resumed ? ", resumed" : "");
  ctx.summary = pipeline::periodic::periodic_summary_json(o, p, s);
}

// The mesh format an output name asks for (.vtu, .vtk, .mesh, .msh, .node, .xdmf); none
// for a container (.tets, -, or any other name).
std::optional<io::MeshFormat> mesh_output(const std::string& path) {
  if (io::is_std_stream(path) || std::filesystem::path(path).extension() == ".tets") return std::nullopt;
  try {
    return io::mesh_format_for(path);
  } catch (const UsageError&) {
    return std::nullopt;
  }
}

void run_run(RunArgs& args, Context& ctx) {
  auto& o = args.options;
  using Placement = pipeline::RunOptions::IndexPlacement;
  o.index = args.index == "disk" ? Placement::kDisk : args.index == "memory" ? Placement::kMemory : Placement::kAuto;
  // `-o out.vtu`: the job writes the container out.vtu.tets (checkpointed and resumable
  // under that name, as any output), then converts it and removes it.
  const std::optional<io::MeshFormat> mesh = mesh_output(o.output);
  const std::string mesh_path = o.output;
  if (mesh) {
    o.output += ".tets";
    // That container is the job's own, removed after the conversion: a file already
    // there is somebody else's, never replaced or removed.
    std::error_code ec;
    if (std::filesystem::symlink_status(o.output, ec).type() != std::filesystem::file_type::not_found)
      throw UsageError(o.output + " exists: run -o " + mesh_path +
                       " writes its container there and removes it after the conversion (move it away, or "
                       "write -o " +
                       o.output + " and convert it)");
  }
  o.memory_bytes = pipeline::parse_memory_size(args.memory);
  o.brick_labels = args.labels.empty() ? args.periodic.empty() : args.labels == "bricks";
  o.threads = ctx.global.threads;
  o.progress = !ctx.global.quiet;
  ctx.stdout_is_data = io::is_std_stream(o.output);
  if (!args.periodic.empty()) {
    if (mesh) throw UsageError("--periodic writes a .tets container: convert it afterwards");
    if (o.brick_labels) throw UsageError("--periodic writes its labels in the sort's order: drop --labels bricks");
    run_periodic(args, ctx);
    return;
  }
  // Under mpirun with several ranks, the distributed job (the same bytes); rank 0
  // reports it.
  pipeline::Communicator& comm = world();
  const pipeline::RunSummary s = comm.size() > 1 ? pipeline::run_job_distributed(o, comm) : pipeline::run_job(o);
  if (comm.rank() != 0) return;
  const double tets_per_s = s.seconds_total > 0 ? double(s.tets) / s.seconds_total : 0;
  spdlog::info("{} points ({} duplicates merged) -> {} tets in {} segments ({} zones); {} written, tets {:.2f} B/tet",
               s.points, s.duplicates, s.tets, s.segments, s.zones, pipeline::human_bytes(double(s.output_bytes)),
               s.tets ? double(s.tet_bytes) / double(s.tets) : 0.0);
  spdlog::info(
      "time: sort {:.2f}s, triangulate {:.2f}s, write {:.2f}s, total {:.2f}s ({} tets/s); redundant insertion "
      "{:.1f}% (segment buffers {}, zone buffers {} = {:.1f}% of insertions, hull {}, repairs {}), {} queries "
      "({} exact tests); segments: build {:.1f}s, check {:.1f}s (summed)",
      s.seconds_sort, s.seconds_triangulate, s.seconds_write, s.seconds_total, pipeline::human_count(tets_per_s),
      100 * s.redundant_ratio(), s.segment_buffer_points, s.zone_buffer_points, 100 * s.zone_buffer_share(),
      s.hull_window_points, s.repair_points, s.queries, s.query_points, s.seconds_build, s.seconds_check);
  ctx.summary = pipeline::run_summary_json(o, s);
  if (!mesh) return;
  std::vector<std::string> files;
  {
    const io::TetReader reader(o.output);
    pipeline::Progress points("converting points", "points", reader.point_count(), o.progress);
    pipeline::Progress tets("converting tets", "tets", reader.tet_count(), o.progress);
    io::MeshExportOptions options;
    options.on_points = [&points](std::uint64_t n) { points.add(n); };
    options.on_tets = [&tets](std::uint64_t n) { tets.add(n); };
    files = io::export_mesh(reader, mesh_path, *mesh, options).files;
    points.finish();
    tets.finish();
  }
  std::filesystem::remove(o.output);
  for (const auto& f : files) spdlog::info("wrote {}", f);
  ctx.summary["mesh"] = mesh_path;
  ctx.summary["mesh_format"] = io::mesh_format_name(*mesh);
  ctx.summary["mesh_files"] = files;
}

void setup_run(CLI::App& app, Context& ctx) {
  auto args = std::make_shared<RunArgs>();
  auto* cmd = app.add_subcommand("run", "Triangulate a point file out of core into a .tets container");
  add_point_input_files(cmd, "input", args->options.input, args->options.read,
                        "Point file (raw, PLY, .npy, text, LAS, HDF5) or - for stdin; several files (or a quoted glob) "
                        "are read in order as one input");
  cmd->add_option("-o,--output", args->options.output,
                  "Output container (.tets), or - to stream it to standard output (a pipe; not resumable);\n"
                  "a mesh name (.vtu .vtk .mesh .msh .node .xdmf) writes that format (through OUT.tets, removed)")
      ->required();
  cmd->add_option("--memory", args->memory, "Memory budget, e.g. 512M, 4G (peak resident memory stays below it)")
      ->capture_default_str();
  cmd->add_option("--tmpdir", args->options.tmpdir, "Directory for temporary files (default: the output's)");
  cmd->add_option("--buffer", args->options.buffer_spacings,
                  "Buffer thickness on each side of a segment, in mean point spacings")
      ->capture_default_str();
  // A segment is a label range of the sorted file, a zone a strip of a segment: the
  // option that sets a segment's size was named --zone-points, which stays an alias.
  cmd->add_option("--segment-points,--zone-points", args->options.segment_points,
                  "Points per segment (default: from --memory; small values force many segments). "
                  "--zone-points is the old name, kept as an alias for one release");
  cmd->add_option("--labels", args->labels,
                  "Label order of the output: bricks (the default: container version 2, bricks along a "
                  "space-filling curve, about half the bytes a tet past 10^7 points) or sorted (version 1, the "
                  "sort's order along the longest axis; the only one --periodic writes)")
      ->check(CLI::IsMember({"sorted", "bricks"}));
  cmd->add_option("--zones", args->options.zones,
                  "Zones per segment (strips across the sort axis, triangulated --threads at a time); "
                  "0: the number that wastes the least on buffers for --memory")
      ->capture_default_str()
      ->check(CLI::Range(0, 4096));
  cmd->add_option("--index", args->index,
                  "Where the point index lives: memory (about 7.5 bytes a point), disk (a file in the work "
                  "directory, its pages held within a sixteenth of --memory), or auto (disk when the index would "
                  "take more than an eighth of --memory). The output is the same")
      ->check(CLI::IsMember({"auto", "memory", "disk"}))
      ->capture_default_str();
  cmd->add_option("--sort-run-points", args->options.sort_run_points,
                  "Points per sorted run (default: from --memory; tests force many runs)")
      ->group("");  // hidden: a testing knob
  cmd->add_option("--checkpoint", args->options.checkpoint_dir,
                  "Directory in which the job makes its checkpoint, OUTPUT.ckpt (default: --tmpdir, else the "
                  "output's directory): the job's working files and progress, removed when it succeeds");
  cmd->add_flag_callback(
      "--no-checkpoint", [args] { args->options.checkpoint = false; },
      "Keep no checkpoint (temporary files in a private directory; the job cannot be resumed)");
  cmd->add_flag("--resume", args->options.resume,
                "Continue the job checkpointed for this output after a crash, kill, Ctrl-C or full disk");
  cmd->add_flag("--force", args->options.force, "Discard an existing checkpoint for this output and start over")
      ->excludes("--resume");
  cmd->add_option("--periodic", args->periodic,
                  "Triangulate the flat 3-torus of this box: L, Lx,Ly,Lz, or auto (the HDF5 input's Header/BoxSize); "
                  "docs/periodic.md");
  cmd->add_option("--periodic-outside", args->outside, "Points outside [0, L): wrap them (exactly) or refuse them")
      ->check(CLI::IsMember({"wrap", "refuse"}))
      ->capture_default_str();
  cmd->add_option("--periodic-margin", args->margin,
                  "First margin of images, in mean point spacings (doubled until the certificate holds; by default 8, "
                  "raised where the points near the faces are sparse)")
      ->group("");
  add_point_input_options(cmd, args->options.read);
  cmd->callback([args, &ctx] { run_run(*args, ctx); });
}

}  // namespace
TETSTREAM_COMMAND(30, setup_run);
}  // namespace tetstream::cli
