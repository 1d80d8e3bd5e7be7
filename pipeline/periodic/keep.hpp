#pragma once
// The keep step of a periodic job (periodic.hpp): from the ordinary job's container of
// the padded points, the periodic tets, each once, certified, and the output written.
//
// The certificate (docs/periodic.md, "Completeness"): when the padded box's 8 corner
// cubes hold points (Images::corners_full), the box of centres C = [t - L, t)^3 lies
// strictly inside the padded set's hull, so every point of C lies in a finite padded
// tet. When every padded tet that may meet C passes the cover (keep_parts.hpp,
// covers_centre_box), the nearest padded point of every point of C is nearer than the
// padded box's faces: then the padded tets with their circumcentres in C are exactly
// the tets of DT(P*) with their circumcentres in C, one copy of each periodic tet, kept.
#include "io/output_file.hpp"
#include "pipeline/periodic/pad.hpp"
#include "pipeline/util/memory_budget.hpp"

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace tetstream::pipeline::periodic {

struct KeepInput {
  std::string padded;              // the ordinary job's container of the padded points
  std::uint64_t input_points = 0;  // N: original indices below N are the points
  const Images* images = nullptr;
  std::array<double, 3> period{}, margin{};
  int sort_axis = 0;
  std::string input, output;  // the user's files (errors name the input)
  const io::OutputClaim* claim = nullptr;
  std::string dir;  // the job's directory (sort runs)
  std::uint64_t memory_bytes = 0;
  // Tets a frame of the output, about (cut at groups): MemoryBudget::frame_tets_for the
  // budget the job started with (its header's), as a plain run's frames.
  std::size_t frame_tets = std::size_t(1) << 18;
  int threads = 1;
  std::string options_json;  // the output header's options
};

struct KeepResult {
  bool complete = false;  // every padded tet that may meet C passed the cover
  std::uint64_t ball_failures = 0;
  std::uint64_t points = 0, tets = 0, output_bytes = 0;
  std::vector<MemoryBudget::Share> memory_shares;  // the keep phase of the ledger (plan_keep)
};

// Writes the output only when the result is complete.
KeepResult keep_periodic_tets(const KeepInput& in);

}  // namespace tetstream::pipeline::periodic
