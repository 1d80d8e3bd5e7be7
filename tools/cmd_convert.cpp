// `tetstream convert OUT.tets MESH`: a container to a mesh file for downstream tools
// (io/mesh_export.hpp): .vtu (VTK), .mesh (Medit), .msh (Gmsh 4.1), .node (TetGen, with
// .ele beside it). Streams in bounded memory; nothing is left behind on failure.
#include "io/mesh_export.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/progress.hpp"
#include "tools/command.hpp"

#include <spdlog/spdlog.h>

#include <memory>

namespace tetstream::cli {
namespace {

struct ConvertArgs {
  std::string input, output;
};

void run_convert(const ConvertArgs& args, Context& ctx) {
  const io::MeshFormat format = io::mesh_format_for(args.output);
  const io::TetReader reader(args.input);
  pipeline::Progress points("converting points", "points", reader.point_count(), !ctx.global.quiet);
  pipeline::Progress tets("converting tets", "tets", reader.tet_count(), !ctx.global.quiet);
  io::MeshExportOptions options;
  options.on_points = [&points](std::uint64_t n) { points.add(n); };
  options.on_tets = [&tets](std::uint64_t n) { tets.add(n); };
  const io::MeshExportResult result = io::export_mesh(reader, args.output, format, options);
  points.finish();
  tets.finish();
  for (const auto& f : result.files) spdlog::info("wrote {}", f);
  ctx.summary = {{"command", "convert"},
                 {"file", args.input},
                 {"format", io::mesh_format_name(format)},
                 {"outputs", result.files},
                 {"points", reader.point_count()},
                 {"tets", reader.tet_count()},
                 {"bytes", result.bytes},
                 {"seconds", tets.seconds()}};
}

void setup_convert(CLI::App& app, Context& ctx) {
  auto args = std::make_shared<ConvertArgs>();
  CLI::App* cmd = app.add_subcommand(
      "convert", "Convert a .tets container to a mesh: .vtu (VTK XML), .mesh (Medit), .msh (Gmsh 4.1)\n"
                 "or .node (TetGen .node + .ele); the format comes from the extension");
  cmd->add_option("input", args->input, ".tets container")->required();
  cmd->add_option("output", args->output, "mesh.vtu, mesh.mesh, mesh.msh or mesh.node")->required();
  cmd->callback([args, &ctx] { run_convert(*args, ctx); });
}

TETSTREAM_COMMAND(60, setup_convert);

}  // namespace
}  // namespace tetstream::cli
