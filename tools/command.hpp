#pragma once
// The frame every subcommand plugs into.
//
// A subcommand is one tools/cmd_NAME.cpp that defines a setup function and registers
// it with TETSTREAM_COMMAND. The setup function adds a CLI11 subcommand to the app,
// binds its options, and sets a callback that does the work. The callback may throw
// tetstream::Error (core/error.hpp); main() maps it to the documented exit code and
// prints the message as one line. A callback fills `ctx.summary`, which main() prints
// as JSON on stdout when the global --json flag is given (on stderr when stdout carries
// the command's data, into FILE with --json-file FILE).
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <functional>
#include <string>
#include <vector>

namespace tetstream::cli {

struct GlobalOptions {
  int threads = 0;  // 0: all cores
  std::string log_level = "info";
  bool json = false;      // machine-readable summary on stdout at the end
  bool quiet = false;     // no progress line, warnings and errors only
  bool verbose = false;   // progress also where a command is quiet by default (cat)
  std::string json_file;  // the --json summary goes to this file instead
};

struct Context {
  GlobalOptions global;
  nlohmann::json summary = nlohmann::json::object();
  // Standard output carries the command's data (a container streamed with -o -): the
  // --json summary goes to stderr instead.
  bool stdout_is_data = false;
};

using CommandSetup = std::function<void(CLI::App& app, Context& ctx)>;

struct CommandRegistration {
  int order;  // position in --help
  CommandSetup setup;
};

std::vector<CommandRegistration>& command_registry();

struct CommandRegistrar {
  CommandRegistrar(int order, CommandSetup setup) { command_registry().push_back({order, std::move(setup)}); }
};

}  // namespace tetstream::cli

#define TETSTREAM_CONCAT_INNER(a, b) a##b
#define TETSTREAM_CONCAT(a, b) TETSTREAM_CONCAT_INNER(a, b)
// Registers a subcommand setup function; ORDER sorts the subcommands in --help.
#define TETSTREAM_COMMAND(ORDER, SETUP) \
  static ::tetstream::cli::CommandRegistrar TETSTREAM_CONCAT(tetstream_command_, __LINE__)(ORDER, SETUP)
