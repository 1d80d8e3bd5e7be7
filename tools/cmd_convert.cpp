// `tetstream convert OUT.tets MESH`: a container to a mesh file for downstream tools
// (io/mesh_export.hpp): .vtu (VTK XML, raw or zlib-compressed), .vtk (legacy VTK, ASCII
// or binary), .mesh (Medit), .msh (Gmsh 4.1, ASCII or binary), .node (TetGen, with .ele
// beside it), .xdmf (with BASE.h5, in a build with HDF5). Streams in bounded memory;
// nothing is left behind on failure.
#include "io/mesh_export.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/util/progress.hpp"
#include "tools/command.hpp"

#include <spdlog/spdlog.h>

#include <memory>

namespace tetstream::cli {
namespace {

struct ConvertArgs {
  std::string input, output;
  bool binary = false;
  int compress = 0;
};

void run_convert(const ConvertArgs& args, Context& ctx) {
  const io::MeshFormat format = io::mesh_format_for(args.output);
  const io::TetReader reader(args.input);
  pipeline::Progress points("converting points", "points", reader.point_count(), !ctx.global.quiet);
  pipeline::Progress tets("converting tets", "tets", reader.tet_count(), !ctx.global.quiet);
  io::MeshExportOptions options;
  options.binary = args.binary;
  options.compress_level = args.compress;
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
                 {"binary", args.binary},
                 {"compress_level", args.compress},
                 {"points", reader.point_count()},
                 {"tets", reader.tet_count()},
                 {"bytes", result.bytes},
                 {"seconds", tets.seconds()}};
}

void setup_convert(CLI::App& app, Context& ctx) {
  auto args = std::make_shared<ConvertArgs>();
  CLI::App* cmd = app.add_subcommand(
      "convert", "Convert a .tets container to a mesh: .vtu (VTK XML), .vtk (legacy VTK), .mesh (Medit),\n"
                 ".msh (Gmsh 4.1), .node (TetGen .node + .ele) or .xdmf (XDMF + HDF5 .h5 beside it);\n"
                 "the format comes from the extension. Each point carries its input index as\n"
                 "\"original_id\" where the format has point data (.vtu .vtk .msh .xdmf; .node: attribute 1)");
  cmd->add_option("input", args->input, ".tets container")->required();
  cmd->add_option("output", args->output, "mesh.vtu, mesh.vtk, mesh.mesh, mesh.msh, mesh.node or mesh.xdmf")->required();
  cmd->add_flag("--binary", args->binary, ".msh and .vtk: binary instead of ASCII");
  cmd->add_flag("--compress{6}", args->compress, ".vtu: zlib-compress the data (vtkZLibDataCompressor); --compress=L for level 1-9");
  cmd->callback([args, &ctx] { run_convert(*args, ctx); });
}

TETSTREAM_COMMAND(60, setup_convert);

}  // namespace
}  // namespace tetstream::cli
