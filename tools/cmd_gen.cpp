// `tetstream gen`: write a seeded synthetic point set (io/point_generators.hpp).
#include "core/error.hpp"
#include "io/point_generators.hpp"
#include "io/point_writer.hpp"
#include "pipeline/util/interrupt.hpp"
#include "pipeline/util/progress.hpp"
#include "tools/command.hpp"
#include "tools/count_option.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <sys/statvfs.h>
#include <memory>
#include <vector>

namespace tetstream::cli {
namespace {

struct GenArgs {
  std::string dist = "uniform";
  io::GeneratorOptions gen;
  std::vector<double> axes;
  std::string output;
  std::string format;
  std::string type;
  std::string byte_order = "little";
  bool ascii = false;
  std::uint64_t chunk = std::uint64_t(1) << 20;  // points per write
};

// Refuses (IoError, exit 3, before any point is written) an output its filesystem
// cannot hold: binary formats by their exact size, text by a lower bound (a digit and
// a separator a coordinate), so a job that could fit is never refused.
void plan_gen_disk(const std::string& output, const std::string& format, std::uint64_t points) {
  std::uint64_t per_point = 6;  // text, PLY ASCII
  if (format.find("raw f64") == 0 || format.find("f8") != std::string::npos)
    per_point = 24;
  else if (format.rfind("raw", 0) == 0 || format.rfind("npy", 0) == 0 || format.find("binary") != std::string::npos)
    per_point = 12;  // float32 records (PLY binary: at least that)
  const std::string::size_type slash = output.rfind('/');
  const std::string dir = slash == std::string::npos ? "." : slash == 0 ? "/" : output.substr(0, slash);
  struct statvfs vfs {};
  if (::statvfs(dir.c_str(), &vfs) != 0)
    throw IoError(dir + ": cannot examine the filesystem: " + std::strerror(errno));
  const std::uint64_t available = std::uint64_t(vfs.f_bavail) * std::uint64_t(vfs.f_frsize);
  const unsigned __int128 need = static_cast<unsigned __int128>(points) * per_point;
  if (need > available)
    throw IoError("not enough disk for " + output + ": " + std::to_string(points) + " points need " +
                  (need >> 64 ? std::string("more than 16 EiB") : pipeline::human_bytes(double(std::uint64_t(need)))) +
                  " in " + dir + ", " + pipeline::human_bytes(double(available)) + " free");
}

void run_gen(const GenArgs& args, Context& ctx) {
  io::GeneratorOptions gopt = args.gen;
  gopt.dist = io::parse_distribution(args.dist);
  if (!args.axes.empty()) {
    if (args.axes.size() != 3) throw UsageError("--axes takes three numbers a,b,c");
    gopt.axes = {args.axes[0], args.axes[1], args.axes[2]};
  }
  if (args.chunk == 0) throw UsageError("--chunk must be at least 1");
  const io::PointGenerator generator(gopt);
  const std::uint64_t total = generator.count();
  if (gopt.dist == io::Distribution::kGrid && total != gopt.n) {
    spdlog::info("grid: --n {} rounded to {} = {}^3 points", gopt.n, total, std::llround(std::cbrt(double(total))));
  }

  io::PointWriteOptions wopt;
  if (!args.format.empty()) io::parse_format_name(args.format, wopt.format, wopt.type);
  if (args.type == "f32")
    wopt.type = io::ScalarType::kFloat32;
  else if (args.type == "f64")
    wopt.type = io::ScalarType::kFloat64;
  wopt.byte_order = io::parse_byte_order(args.byte_order);
  wopt.ascii = args.ascii;

  auto writer = io::create_points(args.output, wopt, total);
  if (args.output != "-") plan_gen_disk(args.output, writer->format_name(), total);
  pipeline::Progress progress("generating", "points", total, !ctx.global.quiet);
  const std::size_t chunk = static_cast<std::size_t>(std::min<std::uint64_t>(args.chunk, total));
  std::vector<double> xyz(3 * chunk);
  constexpr std::size_t kBlock = 4096;  // points per OpenMP work item
  for (std::uint64_t first = 0; first < total; first += chunk) {
    const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(chunk, total - first));
    const std::int64_t blocks = static_cast<std::int64_t>((n + kBlock - 1) / kBlock);
#pragma omp parallel for schedule(static)
    for (std::int64_t b = 0; b < blocks; ++b) {
      const std::size_t lo = std::size_t(b) * kBlock;
      const std::size_t m = std::min(kBlock, n - lo);
      generator.generate(first + lo, m, xyz.data() + 3 * lo);
    }
    writer->write(xyz.data(), n);
    progress.add(n);
    pipeline::check_interrupted();
  }
  writer->commit();
  progress.finish();
  const double seconds = progress.seconds();
  spdlog::info("wrote {} points ({}, {}) to {}", total, writer->format_name(),
               pipeline::human_bytes(double(writer->bytes_written())), args.output);
  ctx.summary = {{"command", "gen"},
                 {"dist", io::to_string(gopt.dist)},
                 {"seed", gopt.seed},
                 {"points", total},
                 {"duplicates", gopt.duplicates},
                 {"output", args.output},
                 {"format", writer->format_name()},
                 {"bytes", writer->bytes_written()},
                 {"seconds", seconds}};
}

void setup_gen(CLI::App& app, Context& ctx) {
  auto args = std::make_shared<GenArgs>();
  CLI::App* cmd = app.add_subcommand("gen", "Generate a seeded synthetic point set");
  cmd->footer(io::distribution_help());
  cmd->add_option("--dist", args->dist,
                  "Distribution: uniform, ball, ellipsoid-shell, mixed, clusters, grid, sphere, terrain, two-plates;\n"
                  "the surface zoo: hills, roofs, canopy, water, strips, scan-lines, survey, indoor;\n"
                  "a periodic box: cosmic")
      ->capture_default_str();
  cmd->add_option("-n,--n", args->gen.n, "Number of points, e.g. 1000000 or 1e6 (grid: rounded to the nearest cube)")
      ->transform(scientific_count())
      ->required();
  cmd->add_option("--seed", args->gen.seed, "Random seed")->capture_default_str();
  cmd->add_option("-o,--output", args->output,
                  "Output file ('-' for stdout); format from the extension: .f64 .raw .bin (raw float64),\n"
                  ".f32 (raw float32), .ply (binary little-endian double), .npy (float64), .txt .xyz (text),\n"
                  ".csv (comma-separated text)")
      ->required();
  cmd->add_option("--format", args->format, "Output format: raw, f32, f64, ply, npy, text (overrides the extension)");
  cmd->add_option("--type", args->type, "Scalar type of raw, PLY binary and npy output: f32 or f64")
      ->check(CLI::IsMember({"f32", "f64"}));
  cmd->add_option("--byte-order", args->byte_order, "Byte order of raw, PLY binary and npy output: little or big")
      ->check(CLI::IsMember({"little", "big"}))
      ->capture_default_str();
  cmd->add_flag("--ascii", args->ascii, "PLY: write ASCII instead of binary");
  cmd->add_option("--duplicates", args->gen.duplicates, "Fraction in [0, 1) of points that copy an earlier point")
      ->capture_default_str();
  cmd->add_option("--axes", args->axes, "ellipsoid-shell semi-axes a,b,c (default 1,0.6,0.3)")->delimiter(',');
  cmd->add_option("--spread", args->gen.spread, "ellipsoid-shell radial spread / mixed noise radius")
      ->capture_default_str();
  cmd->add_option("--clusters", args->gen.clusters, "clusters: number of Gaussian clusters")->capture_default_str();
  cmd->add_option("--radius", args->gen.radius, "sphere: radius")->capture_default_str();
  cmd->add_option("--chunk", args->chunk, "Points generated and written per chunk (the output does not depend on it)")
      ->transform(scientific_count())
      ->capture_default_str();
  cmd->callback([args, &ctx] { run_gen(*args, ctx); });
}

TETSTREAM_COMMAND(10, setup_gen);

}  // namespace
}  // namespace tetstream::cli
