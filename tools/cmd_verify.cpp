// `tetstream verify`: check that a .tets container holds the Delaunay triangulation of
// its points (pipeline/verify.hpp, docs/verify.md).
#include "core/error.hpp"
#include "pipeline/util/progress.hpp"
#include "pipeline/run/run.hpp"
#include "pipeline/run/summary_json.hpp"
#include "pipeline/verify/verify.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/files/temp_files.hpp"
#include "pipeline/periodic/verify.hpp"
#include "tools/command.hpp"
#include "tools/world.hpp"

#include <spdlog/spdlog.h>

#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <memory>

namespace tetstream::cli {
namespace {

constexpr const char* kVerifyHelp =
    "Checks, with exact predicates and the points' labels as the symbolic perturbation:\n"
    "  orientation (every tet), facet pairing (each facet in two tets on opposite sides\n"
    "  or on the hull, no tet twice), local Delaunay (every interior facet), the hull\n"
    "  (closed, V-E+F = 2, locally convex), coverage (every point a vertex), Euler\n"
    "  (V-E+F-T = 1) and volume (tets vs hull, relative tolerance 1e-9).\n"
    "With --sample F < 1 (a quick look): storage and coverage on every tet; orientation\n"
    "on a seeded fraction F of the tets; pairing and local Delaunay on a seeded fraction\n"
    "F of the facets (all copies of a sampled facet, so those checks are exact); no hull,\n"
    "Euler or volume check. See docs/verify.md.\n"
    "Exit status 1 when any violation is found; the first ones are listed with the\n"
    "ordinal of the tet in the file (stored order, from 0).";

struct VerifyArgs {
  std::string input;
  std::string memory = "1G";
  pipeline::VerifyOptions options;
};

// A periodic container (docs/periodic.md): its own checks, in one process.
void run_verify_periodic(VerifyArgs& args, Context& ctx) {
  const char* env = std::getenv("TMPDIR");
  const std::string parent = !args.options.tmpdir.empty() ? args.options.tmpdir : (env && *env ? env : "/tmp");
  pipeline::TempDir tmp(parent, "tetstream-verify");
  const auto r = pipeline::periodic::verify_periodic(args.input, args.options.memory_bytes, tmp.dir());
  ctx.summary = {{"file", args.input},
                 {"periodic", true},
                 {"ok", r.ok},
                 {"tets", r.tets},
                 {"points", r.points},
                 {"vertices", r.vertices},
                 {"edges", r.edges},
                 {"facets", r.facets},
                 {"euler", r.euler},
                 {"unpaired", r.unpaired},
                 {"not_delaunay", r.not_delaunay},
                 {"bad_orientation", r.bad_orientation},
                 {"inexact", r.inexact},
                 {"volume", double(r.volume)},
                 {"box_volume", double(r.expected)}};
  if (!ctx.global.json)
    std::cout << args.input << ": periodic, " << r.tets << " tets, V-E+F-T = " << r.vertices << "-" << r.edges << "+"
              << r.facets << "-" << r.tets << " = " << r.euler << ", volume " << double(r.volume) << " of "
              << double(r.expected) << ": " << (r.ok ? "OK" : r.problem) << std::endl;
  if (!r.ok) throw InputError(args.input + ": verification failed: " + r.problem);
}

void run_verify(VerifyArgs& args, Context& ctx) {
  args.options.memory_bytes = pipeline::parse_memory_size(args.memory);
  if (world().size() == 1 && io::TetReader::is_periodic_file(args.input)) {
    run_verify_periodic(args, ctx);
    return;
  }
  args.options.progress = !ctx.global.quiet;
  // Under mpirun, every rank checks its share (pipeline/verify.hpp); rank 0 reports for
  // the job, the others learn the verdict and exit with its code, silently.
  pipeline::Communicator& comm = world();
  const pipeline::VerifyReport r = pipeline::verify_file(args.input, args.options, comm);
  if (comm.rank() != 0) {
    if (!r.ok()) throw pipeline::PeerFailed(ExitCode::kBadInput);
    return;
  }
  ctx.summary = pipeline::verify_report_json(r, args.input);
  if (!ctx.global.json) {
    std::cout << args.input << ": " << r.summary() << std::endl;
  } else if (!r.ok()) {
    // main() prints the summary only on success; a failed verification still owes it.
    std::cout << ctx.summary.dump(2) << std::endl;
  }
  spdlog::info("verified {} tets in {}", r.tets, pipeline::human_duration(r.seconds));
  if (!r.ok())
    throw InputError(args.input + ": verification failed: " + std::to_string(r.violations()) + " violation(s)");
}

void setup_verify(CLI::App& app, Context& ctx) {
  auto args = std::make_shared<VerifyArgs>();
  CLI::App* cmd =
      app.add_subcommand("verify", "Check that a .tets container is the Delaunay triangulation of its points");
  cmd->footer(kVerifyHelp);
  cmd->add_option("input", args->input, "The container (.tets)")->required();
  cmd->add_option("--sample", args->options.sample, "Check a seeded fraction in (0, 1] of tets and facets (quick look)")
      ->capture_default_str();
  cmd->add_option("--seed", args->options.seed, "Seed of the sample")->capture_default_str();
  cmd->add_option("--memory", args->memory, "Memory budget, e.g. 512M, 4G (beyond it, open facets spill to --tmpdir)")
      ->capture_default_str();
  cmd->add_option("--tmpdir", args->options.tmpdir,
                  "Directory for spilled records (default: $TMPDIR, else the input's)");
  cmd->add_option("--max-listed", args->options.max_listed, "Violations listed per kind (all are counted)")
      ->capture_default_str();
  cmd->add_option("--volume-tolerance", args->options.volume_tolerance, "Relative tolerance of the volume check")
      ->capture_default_str();
  // Hidden: tets a processing step (benchmarks of the step's cost; tests use the API).
  cmd->add_option("--step-tets", args->options.batch_tets, "Tets a processing step")->group("");
  cmd->callback([args, &ctx] { run_verify(*args, ctx); });
}

}  // namespace
TETSTREAM_COMMAND(50, setup_verify);
}  // namespace tetstream::cli
