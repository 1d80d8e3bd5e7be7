// `tetstream convert OUT.tets MESH`: a container to a mesh file for downstream tools
// (io/mesh_export.hpp): .vtu (VTK XML, raw or zlib-compressed), .vtk (legacy VTK, ASCII
// or binary), .mesh (Medit), .msh (Gmsh 4.1, ASCII or binary), .node (TetGen, with .ele
// beside it), .xdmf (with BASE.h5, in a build with HDF5). Streams in bounded memory
// (but for --point-data and --las-attributes, held whole); nothing is left behind on
// failure.
#include "io/las_attributes.hpp"
#include "io/mesh_export.hpp"
#include "io/npy.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/util/progress.hpp"
#include "pipeline/files/temp_files.hpp"
#include "pipeline/periodic/unwrap.hpp"
#include "tools/command.hpp"

#include <spdlog/spdlog.h>

#include <filesystem>
#include <optional>

#include <memory>

namespace tetstream::cli {
namespace {

struct ConvertArgs {
  std::string input, output;
  bool binary = false;
  int compress = 0;
  std::vector<std::string> point_data;  // NAME=FILE.npy
  bool las_attributes = false;
};

// The LAS input a container was made from and the filters it was read with, from the
// header's options (pipeline/run/stage_write.cpp writes them).
std::pair<std::string, io::PointReadOptions> container_input(const io::TetReader& reader) {
  const nlohmann::json made = nlohmann::json::parse(reader.header().options, nullptr, false);
  if (!made.is_object() || !made.contains("input") || !made["input"].is_string())
    throw InputError(reader.path() +
                     ": its header does not name the input it was made from (--las-attributes needs it)");
  if (made.contains("more_inputs"))
    throw InputError(reader.path() + ": made from several files: --las-attributes reads one LAS file");
  io::PointReadOptions read;
  for (const auto& c : made.value("las_classes", nlohmann::json::array()))
    read.las_classes.push_back(c.get<std::uint8_t>());
  const std::string returns = made.value("las_returns", std::string("all"));
  read.las_returns = returns == "last"    ? io::PointReadOptions::LasReturns::kLast
                     : returns == "first" ? io::PointReadOptions::LasReturns::kFirst
                                          : io::PointReadOptions::LasReturns::kAll;
  return {made["input"].get<std::string>(), read};
}

void run_convert(const ConvertArgs& args, Context& ctx) {
  const io::MeshFormat format = io::mesh_format_for(args.output);
  // A periodic container (docs/periodic.md): its tets unwrapped into a plain one first,
  // image points marked by the point field "image".
  std::optional<pipeline::TempDir> tmp;
  std::optional<pipeline::periodic::Unwrapped> unwrapped;
  if (!io::is_std_stream(args.input) && io::TetReader(args.input, io::TetReader::Periodic::kAccept).periodic()) {
    if (args.las_attributes) throw UsageError("convert: --las-attributes does not apply to a periodic container");
    tmp.emplace(std::filesystem::temp_directory_path().string(), "tetstream-run");
    unwrapped = pipeline::periodic::unwrap_periodic(args.input, tmp->dir());
  }
  const io::TetReader reader(unwrapped ? unwrapped->container : args.input);
  pipeline::Progress points("converting points", "points", reader.point_count(), !ctx.global.quiet);
  pipeline::Progress tets("converting tets", "tets", reader.tet_count(), !ctx.global.quiet);
  io::MeshExportOptions options;
  options.binary = args.binary;
  options.compress_level = args.compress;
  options.on_points = [&points](std::uint64_t n) { points.add(n); };
  options.on_tets = [&tets](std::uint64_t n) { tets.add(n); };
  if (unwrapped) options.point_data = unwrapped->point_data;
  if (args.las_attributes) {
    const auto [las_path, las_read] = container_input(reader);
    options.point_data = io::las_point_data(reader, las_path, las_read);
  }
  for (const std::string& spec : args.point_data) {
    const std::size_t eq = spec.find('=');
    if (eq == std::string::npos || eq == 0 || eq + 1 == spec.size())
      throw UsageError("--point-data '" + spec + "': expected NAME=FILE.npy");
    options.point_data.push_back({spec.substr(0, eq), io::read_npy_values(spec.substr(eq + 1), reader.point_count())});
  }
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
                 {"point_data",
                  [&] {
                    std::vector<std::string> names;
                    for (const auto& a : options.point_data) names.push_back(a.name);
                    return names;
                  }()},
                 {"points", reader.point_count()},
                 {"tets", reader.tet_count()},
                 {"bytes", result.bytes},
                 {"seconds", tets.seconds()}};
}

void setup_convert(CLI::App& app, Context& ctx) {
  auto args = std::make_shared<ConvertArgs>();
  CLI::App* cmd =
      app.add_subcommand("convert",
                         "Convert a .tets container to a mesh: .vtu (VTK XML), .vtk (legacy VTK), .mesh (Medit),\n"
                         ".msh (Gmsh 4.1), .node (TetGen .node + .ele) or .xdmf (XDMF + HDF5 .h5 beside it);\n"
                         "the format comes from the extension. Each point carries its input index as\n"
                         "\"original_id\" where the format has point data (.vtu .vtk .msh .xdmf; .node: attribute 1)");
  cmd->add_option("input", args->input, ".tets container")->required();
  cmd->add_option("output", args->output, "mesh.vtu, mesh.vtk, mesh.mesh, mesh.msh, mesh.node or mesh.xdmf")
      ->required();
  cmd->add_flag("--binary", args->binary, ".msh and .vtk: binary instead of ASCII");
  cmd->add_option("--point-data", args->point_data,
                  "Point data from a 1-D .npy array (float64, float32 or integers), one value per point in\n"
                  "the container's point order: NAME=FILE.npy; repeatable; .vtu .vtk .msh .xdmf")
      ->expected(1)
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
  cmd->add_flag("--las-attributes", args->las_attributes,
                "Container made from a LAS file: read its intensity, classification, return number and\n"
                "GPS time (when the point format has it) again, by original id, as point data; refused\n"
                "when the file is gone or changed");
  cmd->add_flag("--compress{6}", args->compress,
                ".vtu: zlib-compress the data (vtkZLibDataCompressor); --compress=L for level 1-9");
  cmd->callback([args, &ctx] { run_convert(*args, ctx); });
}

TETSTREAM_COMMAND(60, setup_convert);

}  // namespace
}  // namespace tetstream::cli
