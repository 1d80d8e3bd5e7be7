#pragma once
// The machine-readable summaries of `run` and `verify`, shared by the CLI (`--json`)
// and the Python module (tetstream.run, tetstream.verify), so both print the same keys.
#include "pipeline/run/run.hpp"
#include "pipeline/verify/verify.hpp"

#include <nlohmann/json.hpp>

#include <string>

namespace tetstream::pipeline {

// What `tetstream run --json` prints for a finished job.
nlohmann::json run_summary_json(const RunOptions& options, const RunSummary& summary);

// What `tetstream verify --json` prints; `path` is the container as the user named it.
nlohmann::json verify_report_json(const VerifyReport& report, const std::string& path);

}  // namespace tetstream::pipeline
