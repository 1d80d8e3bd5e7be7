// `tetstream clean [DIR...]`: removes the work directories that killed jobs left
// behind (pipeline/work_dir.hpp): directories tetstream made (they hold its marker),
// whose lock no process holds. Temporary directories go; checkpoints, which a
// `run --resume` could still continue, are listed and go only with --checkpoints.
// Only the files a job writes are removed, never anything else in them.
#include "pipeline/files/work_dir.hpp"
#include "tools/command.hpp"

#include <spdlog/spdlog.h>

#include <iostream>
#include <memory>

namespace tetstream::cli {
namespace {

struct CleanArgs {
  std::vector<std::string> dirs;
  bool checkpoints = false;
  bool dry_run = false;
};

void run_clean(const CleanArgs& args, Context& ctx) {
  nlohmann::json removed = nlohmann::json::array(), kept = nlohmann::json::array();
  for (const std::string& dir : args.dirs.empty() ? std::vector<std::string>{"."} : args.dirs) {
    for (const pipeline::StaleWorkDir& stale : pipeline::find_stale_work_dirs(dir)) {
      const bool remove = !stale.checkpoint || args.checkpoints;
      const char* kind = stale.checkpoint ? "checkpoint" : "temporary directory";
      if (!remove) {
        spdlog::info("kept {} {} (a job that can be resumed; --checkpoints removes it)", kind, stale.path);
        kept.push_back(stale.path);
      } else if (args.dry_run) {
        std::cout << "would remove " << kind << " " << stale.path << '\n';
        removed.push_back(stale.path);
      } else if (pipeline::remove_stale_work_dir(stale)) {
        spdlog::info("removed {} {}", kind, stale.path);
        removed.push_back(stale.path);
      } else {
        spdlog::warn("{} is left in place: it holds files that tetstream did not write, or a job took it", stale.path);
        kept.push_back(stale.path);
      }
    }
  }
  ctx.summary = {{"command", "clean"}, {"removed", removed}, {"kept", kept}, {"dry_run", args.dry_run}};
}

void setup_clean(CLI::App& app, Context& ctx) {
  auto args = std::make_shared<CleanArgs>();
  CLI::App* cmd =
      app.add_subcommand("clean",
                         "Remove the work directories that killed jobs left in DIR (default: .): only directories\n"
                         "tetstream made whose job no longer runs, and only the files it wrote in them");
  cmd->add_option("dirs", args->dirs, "Directories to look in (not recursively)");
  cmd->add_flag("--checkpoints", args->checkpoints,
                "Remove stale checkpoints too (their jobs cannot be resumed after)");
  cmd->add_flag("-n,--dry-run", args->dry_run, "Only list what would be removed");
  cmd->callback([args, &ctx] { run_clean(*args, ctx); });
}

TETSTREAM_COMMAND(90, setup_clean);

}  // namespace
}  // namespace tetstream::cli
