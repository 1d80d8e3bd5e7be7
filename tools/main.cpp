// tetstream: exact 3D Delaunay triangulation of point sets larger than memory.
#include "core/error.hpp"
#include "pipeline/interrupt.hpp"
#include "tools/command.hpp"

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdio>
#include <iostream>
#include <new>
#include <omp.h>

namespace tetstream::cli {

std::vector<CommandRegistration>& command_registry() {
  static std::vector<CommandRegistration> registry;
  return registry;
}

namespace {

constexpr const char* kExitCodes =
    "Exit codes:\n"
    "  0  success\n"
    "  1  bad input (malformed, truncated or non-finite data; a failed verification; a damaged checkpoint)\n"
    "  2  usage error (unknown option, bad value; a checkpoint exists, or belongs to other input or options)\n"
    "  3  I/O or resource failure (unreadable file, disk full, out of memory): run keeps its checkpoint\n"
    "  130  interrupted (Ctrl-C, SIGTERM): no output under its final name; run keeps its checkpoint\n";

void configure_logging(const GlobalOptions& g) {
  // Logs go to stderr so stdout stays clean for data (`cat`) and the --json summary.
  auto logger = spdlog::stderr_color_mt("tetstream");
  logger->set_pattern("[%H:%M:%S.%e] [%^%l%$] %v");
  spdlog::set_default_logger(logger);
  auto level = spdlog::level::from_str(g.log_level);
  if (g.quiet && level < spdlog::level::warn) level = spdlog::level::warn;
  spdlog::set_level(level);
}

}  // namespace
}  // namespace tetstream::cli

int main(int argc, char** argv) {
  using namespace tetstream;
  using namespace tetstream::cli;

  Context ctx;
  CLI::App app{"tetstream: exact 3D Delaunay triangulation of point sets larger than memory,\n"
               "streamed to a compressed container of tetrahedra."};
  app.footer(kExitCodes);
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("tetstream 0.1.0"));
  app.add_option("--threads", ctx.global.threads, "Worker threads (0: all cores)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--log-level", ctx.global.log_level, "trace, debug, info, warn, error, critical, off")
      ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "critical", "off"}));
  app.add_flag("--json", ctx.global.json, "Print a machine-readable summary on stdout at the end");
  app.add_flag("-q,--quiet", ctx.global.quiet, "No progress line; warnings and errors only");
  // Global options may be given before or after the subcommand.
  app.fallthrough();

  auto& registry = command_registry();
  std::stable_sort(registry.begin(), registry.end(),
                   [](const auto& a, const auto& b) { return a.order < b.order; });
  for (auto& reg : registry) reg.setup(app, ctx);

  app.parse_complete_callback([&ctx] {
    configure_logging(ctx.global);
    pipeline::install_interrupt_handlers();
    if (ctx.global.threads > 0) omp_set_num_threads(ctx.global.threads);
  });

  try {
    app.parse(argc, argv);
  } catch (const CLI::Success& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);
    return static_cast<int>(ExitCode::kUsage);
  } catch (const Error& e) {
    std::fflush(stdout);
    std::cerr << "tetstream: error: " << e.what() << '\n';
    return static_cast<int>(e.code());
  } catch (const std::bad_alloc&) {
    std::cerr << "tetstream: error: out of memory\n";
    return static_cast<int>(ExitCode::kIoFailure);
  } catch (const std::exception& e) {
    std::cerr << "tetstream: error: " << e.what() << '\n';
    return static_cast<int>(ExitCode::kIoFailure);
  }
  if (ctx.global.json) (ctx.stdout_is_data ? std::cerr : std::cout) << ctx.summary.dump(2) << std::endl;
  return 0;
}
