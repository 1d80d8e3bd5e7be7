// tetstream: exact 3D Delaunay triangulation of point sets larger than memory.
#include "core/error.hpp"
#include "io/output_file.hpp"
#include "pipeline/util/interrupt.hpp"
#include "tools/command.hpp"
#include "tools/world.hpp"

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <new>
#include <optional>
#include <string>
#include <vector>
#include <omp.h>
#include <poll.h>
#include <sys/stat.h>
#include <unistd.h>

namespace tetstream::cli {

std::vector<CommandRegistration>& command_registry() {
  static std::vector<CommandRegistration> registry;
  return registry;
}

namespace {

constexpr int kMaxThreads = 1024;

constexpr const char* kExitCodes =
    "Exit codes:\n"
    "  0  success\n"
    "  1  bad input (malformed, truncated or non-finite data; a failed verification; a damaged checkpoint)\n"
    "  2  usage error (unknown option, bad value; a checkpoint exists, or belongs to other input or options)\n"
    "  3  I/O or resource failure (unreadable file, disk full, out of memory): run keeps its checkpoint\n"
    "  130  interrupted (Ctrl-C, SIGTERM): no output under its final name; run keeps its checkpoint\n";

// A process allowed fewer cores than --threads asks for runs its threads in turn, at
// the speed of fewer threads and with the memory of more. The usual cause: mpirun
// binds each rank to one core by default (OpenMPI, for two ranks or fewer).
// (omp_get_num_procs: the cores the process's CPU affinity allows.)
void warn_if_fewer_cores_than_threads(int threads) {
  const int cores = omp_get_num_procs();
  if (cores > 0 && threads > cores)
    spdlog::warn(
        "--threads {} but this process may run on {} core{} (its CPU affinity; under mpirun, add "
        "--bind-to none, or give each rank its cores with --map-by ...:PE={}): the threads will take turns",
        threads, cores, cores == 1 ? "" : "s", threads);
}

// Without --threads a rank takes the cores its affinity allows; with mpirun's default
// binding that is one core a rank, however many the node has. Said (by rank 0) when
// the ranks on this node may use fewer cores than it has.
void warn_if_ranks_leave_cores_idle() {
  const char* local = std::getenv("OMPI_COMM_WORLD_LOCAL_SIZE");
  if (!local) local = std::getenv("MPI_LOCALNRANKS");
  const int ranks_here = local ? std::atoi(local) : 0;
  const int cores = omp_get_num_procs();
  const long online = ::sysconf(_SC_NPROCESSORS_ONLN);
  if (ranks_here > 0 && cores > 0 && long(ranks_here) * cores < online)
    spdlog::warn(
        "each rank may use {} of this node's {} cores ({} rank{} here; mpirun binds ranks to cores): for "
        "more threads a rank, add --bind-to none, or --map-by ppr:R:node:PE=T with --threads T",
        cores, online, ranks_here, ranks_here == 1 ? "" : "s");
}

// Edit distance, for "unknown subcommand runn; did you mean run?".
std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diagonal = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diagonal = up;
    }
  }
  return row[b.size()];
}

// The first word that is neither an option, an option's value nor a subcommand: what
// the user meant as the subcommand, when CLI11 says only that one is required.
std::string unknown_subcommand(const CLI::App& app, int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--threads" || a == "--log-level") {
      ++i;
      continue;
    }
    if (a.empty() || a[0] == '-') continue;
    for (const CLI::App* sub : app.get_subcommands({}))
      if (sub->get_name() == a) return "";
    std::string best;
    std::size_t best_distance = 3;  // suggest only close names
    for (const CLI::App* sub : app.get_subcommands({}))
      if (const std::size_t d = edit_distance(a, sub->get_name()); d < best_distance)
        best_distance = d, best = sub->get_name();
    return "unknown subcommand '" + a + "'" + (best.empty() ? "" : "; did you mean '" + best + "'?");
  }
  return "";
}

void write_all_to_stderr(const char* data, std::size_t size) {
  std::size_t done = 0;
  while (done < size) {
    const ssize_t n = ::write(STDERR_FILENO, data + done, size - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return;  // nowhere left to say it
    done += static_cast<std::size_t>(n);
  }
}

// The job's error line, in one write(2): under mpirun every rank's stderr is a pipe the
// launcher merges, and a line written in pieces (what `std::cerr <<` does, unbuffered)
// can be split by another rank's warning.
void print_error_line(const std::string& message) {
  const std::string line = "tetstream: error: " + message + "\n";
  write_all_to_stderr(line.data(), line.size());
}

// Whether standard output is a pipe or socket whose reader has gone (`| head`): a
// write to it failed with EPIPE, which for a filter is the end of the job, not an
// error (cat and seq stop quietly). Linux's poll() reports POLLERR for such a pipe.
bool stdout_reader_gone() {
  struct stat st {};
  if (::fstat(STDOUT_FILENO, &st) != 0 || !(S_ISFIFO(st.st_mode) || S_ISSOCK(st.st_mode))) return false;
  pollfd p{STDOUT_FILENO, POLLOUT, 0};
  return ::poll(&p, 1, 0) == 1 && (p.revents & POLLERR) != 0;
}

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
  // One command a process: every file it reads or finishes is noted, and no output of
  // it may be one of them (io/output_file.hpp).
  tetstream::io::note_files(true);
  using namespace tetstream;
  using namespace tetstream::cli;

  // MPI first (it may rewrite argv), and last: under mpirun, every rank runs this.
  std::optional<WorldSession> world_session;
  try {
    world_session.emplace(argc, argv);
  } catch (const Error& e) {
    print_error_line(e.what());
    return static_cast<int>(e.code());
  }
  const bool other_rank = world().rank() != 0;

  Context ctx;
  CLI::App app{
      "tetstream: exact 3D Delaunay triangulation of point sets larger than memory,\n"
      "streamed to a compressed container of tetrahedra.",
      "tetstream"};
  app.footer(kExitCodes);
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("tetstream 0.1.0"));
  // Capped: each thread holds a kernel and buffers, and OpenMP runtimes fail (or crash)
  // long before 65536 threads; more threads than cores never help.
  app.add_option("--threads", ctx.global.threads,
                 "Worker threads (0: all cores; at most " + std::to_string(kMaxThreads) + ")")
      ->check(CLI::Range(0, kMaxThreads));
  app.add_option("--log-level", ctx.global.log_level, "trace, debug, info, warn, error, critical, off")
      ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "critical", "off"}));
  app.add_flag(
      "--json", ctx.global.json,
      "Print a machine-readable summary at the end (on stdout; on stderr when stdout\ncarries data: cat, run -o -)");
  app.add_option("--json-file", ctx.global.json_file, "Write the --json summary to FILE (implies --json)")
      ->type_name("FILE");
  app.add_flag("-q,--quiet", ctx.global.quiet, "No progress line; warnings and errors only");
  app.add_flag("-v,--verbose", ctx.global.verbose, "Progress also from commands that are quiet by default (cat)");
  // Global options may be given before or after the subcommand.
  app.fallthrough();

  auto& registry = command_registry();
  std::stable_sort(registry.begin(), registry.end(), [](const auto& a, const auto& b) { return a.order < b.order; });
  for (auto& reg : registry) reg.setup(app, ctx);

  app.parse_complete_callback([&ctx, &app, other_rank] {
    // Under mpirun, rank 0 speaks for the job: the other ranks print errors only (the
    // one that fails prints its line) and no summary.
    if (other_rank) {
      ctx.global.quiet = true;
      ctx.global.log_level = "error";
      ctx.global.json = false;
      ctx.global.json_file.clear();
    }
    // (Every rank refuses; rank 0 says why.)
    if (world().size() > 1)
      for (const CLI::App* sub : app.get_subcommands())
        if (sub->get_name() != "run" && sub->get_name() != "verify") {
          if (other_rank) throw pipeline::PeerFailed(ExitCode::kUsage);
          throw UsageError("only `tetstream run` and `tetstream verify` run under mpirun; start `tetstream " +
                           sub->get_name() + "` as one process");
        }
    configure_logging(ctx.global);
    pipeline::install_interrupt_handlers();
    if (ctx.global.threads > 0) {
      omp_set_num_threads(ctx.global.threads);
      warn_if_fewer_cores_than_threads(ctx.global.threads);
    } else {
      warn_if_ranks_leave_cores_idle();  // only under a launcher (its environment says how many ranks)
    }
  });

  try {
    app.parse(argc, argv);
  } catch (const CLI::Success& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    // One line, like every other error (CLI11 would add a second, "Run with --help").
    const std::string unknown = unknown_subcommand(app, argc, argv);
    print_error_line((unknown.empty() ? std::string(e.what()) : unknown) + " (see tetstream --help)");
    return static_cast<int>(ExitCode::kUsage);
  } catch (const pipeline::PeerFailed& e) {
    return static_cast<int>(e.code());  // the failing rank printed the job's error line
  } catch (const Error& e) {
    // A write to standard output that failed because its reader closed the pipe: the
    // job has unwound through its cleanup; nothing more to say.
    if (ctx.stdout_is_data && e.code() == ExitCode::kIoFailure && stdout_reader_gone()) return 0;
    std::fflush(stdout);
    print_error_line(e.what());
    return static_cast<int>(e.code());
  } catch (const std::bad_alloc&) {
    static constexpr char kOutOfMemory[] = "tetstream: error: out of memory\n";  // no allocation here
    write_all_to_stderr(kOutOfMemory, sizeof kOutOfMemory - 1);
    return static_cast<int>(ExitCode::kIoFailure);
  } catch (const std::exception& e) {
    print_error_line(e.what());
    return static_cast<int>(ExitCode::kIoFailure);
  }
  try {
    if (!ctx.global.json_file.empty()) {
      io::OutputFile f(ctx.global.json_file, 1 << 16);
      f.write(ctx.summary.dump(2) + "\n");
      f.commit();
    } else if (ctx.global.json) {
      (ctx.stdout_is_data ? std::cerr : std::cout) << ctx.summary.dump(2) << std::endl;
    }
  } catch (const Error& e) {
    print_error_line(std::string("--json-file: ") + e.what());
    return static_cast<int>(e.code());
  }
  return 0;
}
