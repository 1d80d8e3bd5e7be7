// `tetstream info FILE`: count, bounding box and format of a point file (read in full,
// so every coordinate is checked finite), or the summary of a .tets container.
#include "core/error.hpp"
#include "io/point_reader.hpp"
#include "io/tet_container.hpp"
#include "pipeline/util/progress.hpp"
#include "tools/command.hpp"
#include "tools/info_tets.hpp"
#include "tools/point_options.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <charconv>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <memory>
#include <vector>

namespace tetstream::cli {
namespace {

struct InfoArgs {
  std::string path;
  io::PointReadOptions read;
  bool check = false;  // containers: read and check every point and frame
};

std::string shortest(double v) {
  char buf[32];
  return std::string(buf, std::to_chars(buf, buf + sizeof buf, v).ptr);
}

// Bounding box of n points, folded into lo/hi. Four points (12 doubles) per step in
// independent lanes, so GCC vectorises it to minpd/maxpd without -ffast-math (the
// reader has already rejected NaN, so the ternary's NaN behaviour does not matter).
void bbox_update(const double* p, std::size_t n, double* lo, double* hi) {
  double l[12], h[12];
  for (int k = 0; k < 12; ++k) l[k] = lo[k % 3], h[k] = hi[k % 3];
  std::size_t i = 0;
  for (; i + 4 <= n; i += 4) {
    const double* q = p + 3 * i;
    for (int k = 0; k < 12; ++k) {
      l[k] = q[k] < l[k] ? q[k] : l[k];
      h[k] = q[k] > h[k] ? q[k] : h[k];
    }
  }
  for (; i < n; ++i) {
    for (int c = 0; c < 3; ++c) {
      l[c] = std::min(l[c], p[3 * i + c]);
      h[c] = std::max(h[c], p[3 * i + c]);
    }
  }
  for (int k = 0; k < 12; ++k) lo[k % 3] = std::min(lo[k % 3], l[k]), hi[k % 3] = std::max(hi[k % 3], h[k]);
}

// A .tets container, known by its magic number whatever its name (a point format
// named with --format is read as points).
bool is_container(const std::string& path, const io::PointReadOptions& read) {
  if (read.format != io::PointFormat::kAuto || io::is_std_stream(path)) return false;
  unsigned char magic[io::kFileMagic.size()] = {};
  FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return std::filesystem::path(path).extension() == ".tets";  // the container reader says why
  const std::size_t n = std::fread(magic, 1, sizeof magic, f);
  std::fclose(f);
  return n == sizeof magic && std::equal(magic, magic + n, io::kFileMagic.begin());
}

// An HDF5 file named by extension, --format or its signature.
bool is_hdf5(const std::string& path, const io::PointReadOptions& read) {
  if (read.format == io::PointFormat::kHdf5) return true;
  if (read.format != io::PointFormat::kAuto || io::is_std_stream(path)) return false;
  if (io::format_from_extension(path).format == io::PointFormat::kHdf5) return true;
  if (io::format_from_extension(path).format != io::PointFormat::kAuto) return false;
  char magic[8] = {};
  FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return false;
  const std::size_t n = std::fread(magic, 1, sizeof magic, f);
  std::fclose(f);
  return io::sniff_format(magic, n) == io::PointFormat::kHdf5;
}

// `info FILE.hdf5` without --dataset: the datasets that --dataset can name.
void info_hdf5(const std::string& path, Context& ctx) {
  const auto list = io::list_hdf5_point_datasets(path);
  nlohmann::json datasets = nlohmann::json::array();
  for (const auto& d : list) datasets.push_back({{"path", d.path}, {"rows", d.rows}, {"type", d.type}});
  if (!ctx.global.json) {
    std::printf("file:    %s\n", path.c_str());
    std::printf("format:  hdf5\n");
    std::printf("(N, 3) datasets (read one with --dataset PATH):%s\n", list.empty() ? " none" : "");
    for (const auto& d : list) {
      std::printf("  %s  %llu x 3 %s\n", d.path.c_str(), static_cast<unsigned long long>(d.rows), d.type.c_str());
    }
    std::fflush(stdout);
  }
  ctx.summary = {{"command", "info"}, {"file", path}, {"format", "hdf5"}, {"datasets", datasets}};
}

void info_points(const InfoArgs& args, Context& ctx) {
  auto reader = io::open_points(args.path, args.read);
  // Progress in points when the count is known, else in bytes of a file of known size.
  const bool by_bytes = !reader->count() && reader->source_size();
  pipeline::Progress progress("reading", by_bytes ? "bytes" : "points",
                              by_bytes ? *reader->source_size() : reader->count().value_or(0), !ctx.global.quiet);

  constexpr std::size_t kChunk = std::size_t(1) << 18;  // 6 MiB of doubles
  std::vector<double> xyz(3 * kChunk);
  double lo[3], hi[3];
  std::fill(lo, lo + 3, std::numeric_limits<double>::infinity());
  std::fill(hi, hi + 3, -std::numeric_limits<double>::infinity());
  std::uint64_t last_bytes = 0;
  while (const std::size_t n = reader->read(xyz.data(), kChunk)) {
    bbox_update(xyz.data(), n, lo, hi);
    if (by_bytes) {
      progress.add(reader->bytes_read() - last_bytes);
      last_bytes = reader->bytes_read();
    } else {
      progress.add(n);
    }
  }
  progress.finish();
  const double seconds = progress.seconds();
  const std::uint64_t points = reader->points_read();
  const std::uint64_t bytes = reader->bytes_read();

  if (!ctx.global.json) {
    std::printf("file:    %s\n", reader->source_name().c_str());
    std::printf("format:  %s\n", reader->format_name().c_str());
    std::printf("points:  %llu\n", static_cast<unsigned long long>(points));
    for (int c = 0; c < 3; ++c) {
      std::printf("%s:       [%s, %s]\n",
                  c == 0   ? "x"
                  : c == 1 ? "y"
                           : "z",
                  shortest(lo[c]).c_str(), shortest(hi[c]).c_str());
    }
    std::printf("bytes:   %llu (%s)\n", static_cast<unsigned long long>(bytes),
                pipeline::human_bytes(double(bytes)).c_str());
    for (const auto& [label, value] : reader->details()) {
      std::printf("%-8s %s\n", (label + ":").c_str(), value.c_str());
    }
    std::fflush(stdout);
  }
  spdlog::debug("read {} in {} ({:.0f} MB/s)", pipeline::human_bytes(double(bytes)), pipeline::human_duration(seconds),
                seconds > 0 ? double(bytes) / seconds / 1e6 : 0.0);
  ctx.summary = {{"command", "info"},
                 {"file", reader->source_name()},
                 {"format", reader->format_name()},
                 {"points", points},
                 {"bbox", {{"min", {lo[0], lo[1], lo[2]}}, {"max", {hi[0], hi[1], hi[2]}}}},
                 {"bytes", bytes},
                 {"seconds", seconds},
                 {"mb_per_s", seconds > 0 ? double(bytes) / seconds / 1e6 : 0.0}};
  for (const auto& [label, value] : reader->details()) ctx.summary[label] = value;
}

void setup_info(CLI::App& app, Context& ctx) {
  auto args = std::make_shared<InfoArgs>();
  CLI::App* cmd =
      app.add_subcommand("info",
                         "Show a point file's count, bounding box and format (reads it all and checks every\n"
                         "coordinate), or a .tets container's summary");
  add_point_input_files(cmd, "file", args->path, args->read,
                        "Point file ('-' for stdin; several files are one input) or .tets container; an HDF5 file "
                        "without --dataset: its (N, 3) datasets");
  add_point_input_options(cmd, args->read);
  cmd->add_flag("--check", args->check, "For a .tets container: also read every point and frame and check their CRCs");
  cmd->callback([args, &ctx] {
    if (args->read.more_inputs.empty() && is_container(args->path, args->read)) {
      info_tets(args->path, ctx, args->check);
    } else if (args->read.datasets.empty() && args->read.more_inputs.empty() && is_hdf5(args->path, args->read)) {
      info_hdf5(args->path, ctx);
    } else {
      info_points(*args, ctx);
    }
  });
}

TETSTREAM_COMMAND(40, setup_info);

}  // namespace
}  // namespace tetstream::cli
