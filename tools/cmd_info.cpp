// `tetstream info FILE`: count, bounding box and format of a point file (read in full,
// so every coordinate is checked finite), or the summary of a .tets container.
#include "core/error.hpp"
#include "io/point_reader.hpp"
#include "pipeline/progress.hpp"
#include "tools/command.hpp"
#include "tools/info_tets.hpp"
#include "tools/point_options.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <charconv>
#include <cstdio>
#include <limits>
#include <memory>
#include <vector>

namespace tetstream::cli {
namespace {

struct InfoArgs {
  std::string path;
  io::PointReadOptions read;
};

bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

std::string shortest(double v) {
  char buf[32];
  return std::string(buf, std::to_chars(buf, buf + sizeof buf, v).ptr);
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
    double l0 = lo[0], l1 = lo[1], l2 = lo[2], h0 = hi[0], h1 = hi[1], h2 = hi[2];
    const double* p = xyz.data();
    for (std::size_t i = 0; i < n; ++i) {
      l0 = std::min(l0, p[3 * i]), h0 = std::max(h0, p[3 * i]);
      l1 = std::min(l1, p[3 * i + 1]), h1 = std::max(h1, p[3 * i + 1]);
      l2 = std::min(l2, p[3 * i + 2]), h2 = std::max(h2, p[3 * i + 2]);
    }
    lo[0] = l0, lo[1] = l1, lo[2] = l2, hi[0] = h0, hi[1] = h1, hi[2] = h2;
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
      std::printf("%s:       [%s, %s]\n", c == 0 ? "x" : c == 1 ? "y" : "z", shortest(lo[c]).c_str(),
                  shortest(hi[c]).c_str());
    }
    std::printf("bytes:   %llu (%s)\n", static_cast<unsigned long long>(bytes),
                pipeline::human_bytes(double(bytes)).c_str());
    std::fflush(stdout);
  }
  spdlog::debug("read {} in {} ({:.0f} MB/s)", pipeline::human_bytes(double(bytes)),
                pipeline::human_duration(seconds), seconds > 0 ? double(bytes) / seconds / 1e6 : 0.0);
  ctx.summary = {{"command", "info"},
                 {"file", reader->source_name()},
                 {"format", reader->format_name()},
                 {"points", points},
                 {"bbox", {{"min", {lo[0], lo[1], lo[2]}}, {"max", {hi[0], hi[1], hi[2]}}}},
                 {"bytes", bytes},
                 {"seconds", seconds},
                 {"mb_per_s", seconds > 0 ? double(bytes) / seconds / 1e6 : 0.0}};
}

void setup_info(CLI::App& app, Context& ctx) {
  auto args = std::make_shared<InfoArgs>();
  CLI::App* cmd = app.add_subcommand(
      "info", "Show a point file's count, bounding box and format (reads it all and checks every\n"
              "coordinate), or a .tets container's summary");
  cmd->add_option("file", args->path, "Point file ('-' for stdin) or .tets container")->required();
  add_point_input_options(cmd, args->read);
  cmd->callback([args, &ctx] {
    if (ends_with(args->path, ".tets")) {
      info_tets(args->path, ctx);
    } else {
      info_points(*args, ctx);
    }
  });
}

TETSTREAM_COMMAND(40, setup_info);

}  // namespace
}  // namespace tetstream::cli
