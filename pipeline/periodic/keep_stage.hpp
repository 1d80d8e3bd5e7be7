#pragma once
// The keep of a periodic job inside its padded job (docs/periodic.md, "Keep", "Write"):
// the output stage (pipeline/run/output_stage.hpp) that the ordinary job on the padded
// points runs in place of its write stage, so the padded tets are never encoded,
// written, read back or decoded. Each zone's tets are certified and kept on the thread
// that triangulated it (zone_done: the code words and places of its window's points,
// the cover of every tet that may meet the box of centres C, the copies whose
// circumcentres lie in C kept in place);
// each segment's kept tets then go, merged by smallest padded label, to the stream of
// kept_stream.hpp, which writes them in the stored order behind the frontier, and the
// periodic container is written as the segments finish, on the writer's own thread.
//
// Its record in the padded job's checkpoint ("keep", after each segment, saved once
// the frames before it are on disk): the output's committed bytes, the label the
// triangulation goes on from, the frame being filled and the tets waiting for the
// frontier (files of their own), the bytes of two append-only files (the tets written
// last, through the external sort at the end; each frame's compressed offsets), the
// counters. A resumed keep restores all of it and writes the bytes of an uninterrupted
// one. "finishing": every frame is in, only POFS, the index and the rename are left.
//
// A ball that leaves the padded box stops the job (BallsLeaveBox: its margin doubles)
// and empties the output; an edge of sqrt(0.166) periods or more refuses the input
// once every tet is in (as the keep step after the padded job: keep.hpp).
#include "io/output_file.hpp"
#include "pipeline/periodic/keep.hpp"
#include "pipeline/periodic/pad.hpp"
#include "pipeline/run/output_stage.hpp"
#include "pipeline/run/run_internal.hpp"
#include "pipeline/run/stage.hpp"
#include "pipeline/util/memory_budget.hpp"
#include "pipeline/window/sorted_view.hpp"

#include <array>
#include <cstdint>
#include <memory>
#include <string>

namespace tetstream::pipeline::periodic {

struct KeepSetup {
  std::uint64_t input_points = 0;  // N: original indices below N are the points
  const Images* images = nullptr;
  std::array<double, 3> period{}, margin{};
  std::string input, output;  // the user's files (errors name the input)
  const io::OutputClaim* claim = nullptr;
  std::size_t frame_tets = std::size_t(1) << 18;  // as KeepInput::frame_tets
  std::string options_json;                       // the output header's options
  std::uint64_t waiting_bytes = 0;                // the tets waiting for the frontier, before the stream spills
  std::uint64_t sort_bytes = 0;  // the external sort of the tets written last (after the triangulation)
};

// A tet that may meet the box of centres fails the cover (a ball too large for the
// margin): the attempt is given up, its output emptied, and the periodic job doubles
// the margin.
struct BallsLeaveBox : detail::JobAbandoned {
  using detail::JobAbandoned::JobAbandoned;
};

// The stage for the padded job's Job::run (detail::run_job's factory); `result` is
// filled when the output is complete.
std::unique_ptr<OutputStage> make_keep_stage(const StageContext& context, const SortedView& view,
                                             const TriangulateShares& shares, const KeepSetup& setup,
                                             KeepResult& result);

// What the keep holds during the triangulation beside the padded job's own shares:
// its label tables, the tets waiting for the frontier and the offsets; the padded job
// runs within the rest of --memory.
std::uint64_t keep_stage_bytes(std::uint64_t padded_points, std::uint64_t input_points, std::uint64_t images,
                               std::uint64_t waiting_bytes, int threads);

}  // namespace tetstream::pipeline::periodic
