#include "pipeline/periodic/periodic.hpp"

#include "pipeline/run/summary_json.hpp"

#include "core/error.hpp"
#include "io/output_file.hpp"
#include "io/point_reader.hpp"
#include "pipeline/files/temp_files.hpp"
#include "pipeline/periodic/keep.hpp"
#include "pipeline/periodic/pad.hpp"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <sstream>
#include <thread>

namespace tetstream::pipeline::periodic {

namespace {
double seconds_since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

std::string work_parent(const RunOptions& o) {
  std::string dir = o.tmpdir;
  if (dir.empty()) dir = std::filesystem::path(o.output).parent_path().string();
  return dir.empty() ? "." : dir;
}

// The first margin: `spacings` mean spacings of the box's N points, at most half a
// period (where every image is exact by Sterbenz's lemma).
std::array<double, 3> first_margin(const PeriodicOptions& p, std::uint64_t n) {
  const double volume = p.period[0] * p.period[1] * p.period[2];
  const double spacing = std::cbrt(volume / double(std::max<std::uint64_t>(n, 1)));
  std::array<double, 3> m;
  for (int k = 0; k < 3; ++k) m[k] = std::min(p.margin_spacings * spacing, 0.5 * p.period[k]);
  return m;
}

// The ordinary job on the padded points: the same options but for the files.
RunOptions padded_job(const RunOptions& o, const WrappedInput& points, const Images& images, const std::string& dir) {
  RunOptions inner = o;
  inner.input = points.path;
  inner.read = io::PointReadOptions{};
  inner.read.format = io::PointFormat::kRaw;
  inner.read.type = io::ScalarType::kFloat64;
  if (!images.code.empty()) inner.read.more_inputs = {images.path};
  inner.output = dir + "/periodic-padded.tets";
  inner.tmpdir = dir;
  inner.checkpoint = false;
  inner.resume = inner.force = false;
  return inner;
}

std::string header_options(const RunOptions& o, const PeriodicOptions& p, const std::array<double, 3>& margin) {
  nlohmann::json j;
  j["command"] = "run";
  j["periodic"] = p.period;
  j["margin"] = margin;
  j["memory"] = o.memory_bytes;
  return j.dump();
}
}  // namespace

void PeriodicOptions::validate() const {
  for (double l : period) {
    if (!std::isfinite(l) || !(l > 0)) throw UsageError("--periodic: every period must be a positive number");
  }
  if (!(margin_spacings > 0)) throw UsageError("--periodic-margin must be positive");
}

std::array<double, 3> parse_period(const std::string& text, const std::string& input) {
  if (text == "auto") return io::hdf5_box_size(input);
  std::vector<double> v;
  std::stringstream s(text);
  std::string item;
  while (std::getline(s, item, ',')) {
    std::size_t used = 0;
    double x = 0;
    try {
      x = std::stod(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != item.size()) throw UsageError("--periodic " + text + ": not a number: " + item);
    v.push_back(x);
  }
  if (v.size() == 1) return {v[0], v[0], v[0]};
  if (v.size() != 3) throw UsageError("--periodic " + text + ": give L, Lx,Ly,Lz or auto");
  return {v[0], v[1], v[2]};
}

PeriodicSummary run_periodic(const RunOptions& options, const PeriodicOptions& periodic) {
  const auto start = std::chrono::steady_clock::now();
  periodic.validate();
  options.validate();
  if (io::is_std_stream(options.input) || io::is_std_stream(options.output))
    throw UsageError("--periodic needs an input file and an output file (not standard input or output)");
  if (options.resume) throw UsageError("--periodic jobs cannot be resumed yet (docs/periodic.md): rerun the job");
  io::refuse_input_as_output(options.input, options.output);
  for (const std::string& more : options.read.more_inputs) io::refuse_input_as_output(more, options.output);
  const io::OutputClaim claim(options.output);
  TempDir tmp(work_parent(options), "tetstream-run");

  PeriodicSummary sum;
  const WrappedInput points = write_wrapped(options.input, options.read, periodic.period, periodic.wrap, tmp.dir());
  sum.input_points = points.count;
  sum.wrapped = points.wrapped;
  std::array<double, 3> margin = first_margin(periodic, points.count);
  sum.seconds_pad += seconds_since(start);
  for (;;) {
    ++sum.attempts;
    auto t = std::chrono::steady_clock::now();
    const Images images = write_images(points, periodic.period, margin, tmp.dir());
    sum.images = images.code.size();
    sum.seconds_pad += seconds_since(t);
    if (images.corners_full) {
      const RunOptions inner = padded_job(options, points, images, tmp.dir());
      sum.padded = run_job(inner);
      t = std::chrono::steady_clock::now();
      KeepInput in;
      in.padded = inner.output;
      in.input_points = points.count;
      in.images = &images;
      in.period = periodic.period;
      in.margin = margin;
      in.sort_axis = sum.padded.axis;
      in.input = options.input;
      in.output = options.output;
      in.claim = &claim;
      in.dir = tmp.dir();
      in.memory_bytes = options.memory_bytes;
      in.threads = options.threads > 0 ? options.threads : int(std::max(1u, std::thread::hardware_concurrency()));
      in.options_json = header_options(options, periodic, margin);
      const KeepResult kept = keep_periodic_tets(in);
      remove_file(inner.output);
      sum.seconds_keep += seconds_since(t);
      sum.ball_failures = kept.ball_failures;
      if (kept.complete) {
        sum.points = kept.points;
        sum.tets = kept.tets;
        sum.output_bytes = kept.output_bytes;
        sum.margin = margin;
        break;
      }
      spdlog::info("periodic: {} balls leave the padded box at margin {:.4g}: doubling it", kept.ball_failures,
                   margin[0]);
    } else {
      spdlog::info("periodic: a corner of the padded box is empty at margin {:.4g}: doubling it", margin[0]);
    }
    if (margin[0] >= periodic.period[0] && margin[1] >= periodic.period[1] && margin[2] >= periodic.period[2]) {
      throw InputError(options.input + ": the periodic Delaunay triangulation of these " +
                       std::to_string(points.count) +
                       " points is not certified in the 1-sheeted covering (an empty ball reaches across a whole "
                       "period): too few points for the box (docs/periodic.md, \"When it refuses\")");
    }
    for (int k = 0; k < 3; ++k) margin[k] = std::min(2 * margin[k], periodic.period[k]);
  }
  sum.seconds_total = seconds_since(start);
  return sum;
}

nlohmann::json periodic_summary_json(const RunOptions& options, const PeriodicOptions& periodic,
                                     const PeriodicSummary& s) {
  nlohmann::json j = run_summary_json(options, s.padded);
  j["periodic"] = {{"period", periodic.period},
                   {"margin", s.margin},
                   {"points", s.points},
                   {"input_points", s.input_points},
                   {"wrapped", s.wrapped},
                   {"images", s.images},
                   {"tets", s.tets},
                   {"attempts", s.attempts},
                   {"seconds_pad", s.seconds_pad},
                   {"seconds_keep", s.seconds_keep},
                   {"seconds_total", s.seconds_total},
                   {"output_bytes", s.output_bytes}};
  return j;
}

}  // namespace tetstream::pipeline::periodic
