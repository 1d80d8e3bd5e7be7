#pragma once
// The point-input options every subcommand that reads points shares (`info`, `run`, ...):
//   --format raw|f32|f64|ply|npy|text   --type f32|f64   --stride BYTES   --offset BYTES
//   --byte-order little|big
// Values are checked while parsing (UsageError, exit 2); io::open_points checks the rest.
#include "io/point_reader.hpp"

#include <CLI/CLI.hpp>

namespace tetstream::cli {

void add_point_input_options(CLI::App* app, io::PointReadOptions& options);

}  // namespace tetstream::cli
