#pragma once
// The point-input options every subcommand that reads points shares (`info`, `run`, ...):
//   --format raw|f32|f64|ply|npy|text|las|hdf5   --type f32|f64   --stride BYTES
//   --offset BYTES   --byte-order little|big   --columns X,Y,Z   --properties X,Y,Z
//   --dataset PATH (repeatable)   --las-classes C,C,...   --las-returns last|first|all
// Values are checked while parsing (UsageError, exit 2); io::open_points checks the rest.
#include "io/point_reader.hpp"

#include <CLI/CLI.hpp>

namespace tetstream::cli {

void add_point_input_options(CLI::App* app, io::PointReadOptions& options);

// The positional input: one or more files of one input (a snapshot's files; quoted globs
// are expanded in natural order, io::expand_inputs). The first goes to `first`, the rest
// to options.more_inputs.
CLI::Option* add_point_input_files(CLI::App* app, const std::string& name, std::string& first,
                                   io::PointReadOptions& options, const std::string& help);

}  // namespace tetstream::cli
