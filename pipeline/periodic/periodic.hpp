#pragma once
// `tetstream run --periodic L`: the Delaunay triangulation of points on the flat
// 3-torus [0, Lx) x [0, Ly) x [0, Lz) (docs/periodic.md has the definition and the
// proof):
//
//   pad      the points (wrapped into the box, or refused) and their images p - L on
//            each axis where p lies within the margin M of the upper face: exactly the
//            periodic point set inside [-M, L)^3, every image exact (Sterbenz, or
//            checked);
//   run      the ordinary exact job on them (run_job), unchanged: its labels are the
//            points' lexicographic order, which a translation keeps, so its symbolic
//            perturbation is the same for a point and its images;
//   keep     each tet whose circumcentre lies in the box of centres C = [-M/2, L - M/2)
//            on each axis (decided exactly), once every tet that may meet C passes the
//            cover (its sphere small enough for the margin, conservatively) and the
//            box's corners hold points (the certificate, keep.hpp); otherwise the
//            margin doubles and the job repeats, up to M = L;
//   write    the original points in label order and the kept tets with their vertex
//            offsets (io/tet_periodic.hpp), through the job's claim on the output.
//
// Checkpoint (docs/periodic.md, "Resume and mpirun"): the job's own, OUT.ckpt, as a
// plain run's: its state.json (the job's identity, the periodic options, the current
// margin, the padded job once it is complete, the result once written), the padded
// input (deterministic, rewritten on a resume only when its bytes differ), the padded
// job's checkpoint nested in it (OUT.ckpt/periodic-padded.tets.ckpt) and its output
// (fingerprinted in the state). A resume continues the padded job or, when it had
// finished, redoes only the keep step.
//
// Under mpirun (comm of several ranks): rank 0 pads, every rank runs the padded job
// (run_job_distributed), rank 0 keeps and writes: the same bytes as one process.
#include "io/tet_periodic.hpp"
#include "pipeline/run/run.hpp"
#include "pipeline/util/communicator.hpp"

#include <nlohmann/json.hpp>

#include <array>
#include <cstdint>
#include <string>

namespace tetstream::pipeline::periodic {

struct PeriodicOptions {
  std::array<double, 3> period{0, 0, 0};
  bool wrap = true;              // points outside [0, L): wrapped (exactly), else refused
  double margin_spacings = 4.0;  // the first margin, in mean point spacings (at most L)
  // And raised where the points near the faces are sparse (margin.hpp); off when the
  // user gives the margin.
  bool margin_from_density = true;
  void validate() const;  // throws UsageError
};

struct PeriodicSummary {
  RunSummary padded;  // the ordinary job on the padded points (the last attempt's)
  std::uint64_t input_points = 0, points = 0, wrapped = 0, images = 0, tets = 0;
  std::uint64_t attempts = 0, ball_failures = 0;  // the last attempt's failures: 0
  std::array<double, 3> margin{0, 0, 0};
  double seconds_pad = 0, seconds_keep = 0, seconds_write = 0, seconds_total = 0;
  std::uint64_t output_bytes = 0;
  bool resumed = false;  // continued a checkpoint (the padded job, or the whole job, done before)
  // The wrapped points were written to the job's directory (pad.hpp); false when the
  // padded job read the input itself (raw float64, already inside the box).
  bool input_copied = true;
};

// Parses "L", "Lx,Ly,Lz" or "auto" (the HDF5 input's Header/BoxSize attribute).
// Throws UsageError.
std::array<double, 3> parse_period(const std::string& text, const std::string& input);

// Rank 0's summary holds the job's figures; the other ranks' only their padded part.
PeriodicSummary run_periodic(const RunOptions& options, const PeriodicOptions& periodic,
                             Communicator& comm = single_process());

// The --json summary of a periodic job: the padded job's (run_summary_json) with a
// "periodic" object, for the CLI and the Python module alike.
nlohmann::json periodic_summary_json(const RunOptions& options, const PeriodicOptions& periodic,
                                     const PeriodicSummary& s);

}  // namespace tetstream::pipeline::periodic
