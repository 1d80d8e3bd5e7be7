#pragma once
// The write stage of `run`: the output container. The tets of each finished segment, merged
// by minimum label into frames (pipeline/frame_cutter.hpp), go to the writer on its
// own thread (pipeline/async_tet_writer.hpp) behind a bounded queue of frames, so
// compression and I/O overlap the triangulation.
//
// Its records in the checkpoint state: "header_memory", the budget the output's
// header names (the first process's: a resumed job may run with another, and the
// frames' size depends on this one only, MemoryBudget::frame_tets_for); and "output", replaced after each segment: the
// partial file's committed bytes, the label below which every tet is written (`next_label`), the tets of the frame
// being filled (a file `pending-K.tets` of its own), the segments written and their counters. The triangulation's
// progress is this record: the labels below next_label are done exactly when their tets are committed, so the two are
// recorded as one.
#include "io/output_file.hpp"
#include "io/tet_writer.hpp"
#include "pipeline/write/async_tet_writer.hpp"
#include "pipeline/write/brick_reorder.hpp"
#include "pipeline/write/frame_cutter.hpp"
#include "pipeline/write/label_order.hpp"
#include "pipeline/sort/point_sort.hpp"
#include "pipeline/window/zone_triangulator.hpp"
#include "pipeline/run/output_stage.hpp"
#include "pipeline/run/stage.hpp"
#include "pipeline/run/stage_triangulate.hpp"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

namespace tetstream::pipeline {

nlohmann::json counters_json(const WrittenWork& w);
WrittenWork counters_from(const nlohmann::json& j);
// The summary's counters of the segments' work.
void record_work(const WrittenWork& w, RunSummary& s);

// The budget the output's header names: the first process's, recorded in the state
// ("header_memory") by whichever stage asks first; a resumed job may run with another.
std::uint64_t header_memory(nlohmann::json& state, const RunOptions& options);
// The container's header for the sorted points (the sort's merge writes it first when
// the points go straight into the output: pipeline/points_in_output.hpp).
io::TetFileHeader container_header(const RunOptions& options, std::uint64_t memory, const SortedPoints& sorted);

class WriteStage final : public OutputStage {
 public:
  // `shares`: the writer's compression threads and its file buffer, its memory share
  // with the frames in flight (MemoryBudget::plan_triangulate). `claim`: the output, locked for this
  // job since it began (null for standard output).
  WriteStage(const StageContext& context, const SortedPoints& sorted, const SortedView& view,
             const TriangulateShares& shares, const io::OutputClaim* claim)
      : context_(context),
        sorted_(sorted),
        view_(view),
        encoders_(shares.encoders),
        file_buffer_bytes_(shares.file_buffer_bytes),
        claim_(claim) {}

  // The frames of this process's label range go to a fragment file at `path`
  // (io::TetWriter::fragment) instead of the container, which another process
  // assembles (a rank other than 0 under MPI: pipeline/run_distributed.cpp); the
  // checkpoint's files of the frame being filled are named `prefix`N.tets. Before
  // prepare().
  void write_fragment(std::string path, std::string prefix) {
    fragment_path_ = std::move(path);
    pending_prefix_ = std::move(prefix);
  }
  // Opens the output: a new container, or the checkpoint's partial output reopened at
  // its last commit with the frame that was being filled and the counters
  // (DamagedCheckpoint when the partial file or the pending tets disagree with it).
  void prepare() override;
  // Starts the writer's thread: the points section of a new output (a pass over the
  // sorted file, overlapped with the first zones), and the first record.
  void run() override;
  // One more segment, its zones' tets in plan order: merged by minimum label into the
  // frames, its counters added, and the record says the labels below `next_label` are
  // written. The record is saved by the writer's thread once the frames before it are
  // on disk, so the triangulation never waits for the writer.
  void add_segment(const std::vector<ZoneTets>& parts, const SegmentStats& work, std::uint64_t points,
                   std::uint64_t next_label) override;
  // Every tet of the labels below `end_label` (all of them; a rank's: the end of its
  // range) is in: the last frame, the last record (waiting for the writer), and the
  // mark that only the container's index, footer and rename are left.
  void commit(std::uint64_t end_label = ~std::uint64_t(0)) override;
  // After commit(), on the process that writes the container: flushes (and syncs) its
  // frames and returns the output's size, where the other ranks' frames go, their
  // label ranges in label order (io::place_fragment), before adopt_fragments()
  // indexes them.
  std::uint64_t fragments_offset();
  // The frames others placed after fragments_offset(), `bytes` of them, in order.
  void adopt_fragments(std::vector<io::FrameEntry> frames, std::uint64_t bytes);
  // With --labels bricks, commit() puts the points section in format 2's order
  // (pipeline/write/points_reorder.hpp), which no process may read in the sort's order
  // after, and removes the label order's file: rank 0 of several calls
  // defer_points_order() first and reorder_points_section() once every rank is done.
  void defer_points_order() { defer_points_order_ = true; }
  void reorder_points_section();
  // The index, footer and rename (a fragment: its rename). Nothing may follow it.
  void finish() override;

  double busy_seconds() const override { return async_->busy_seconds(); }
  double producer_wait_seconds() const override { return async_->producer_wait_seconds(); }
  std::uint64_t bytes_written() const override { return writer_->bytes_written(); }
  std::uint64_t tet_bytes() const override { return writer_->tet_bytes(); }

 private:
  void record(std::uint64_t next_label, bool wait);

  StageContext context_;
  const SortedPoints& sorted_;
  const SortedView& view_;
  const int encoders_;
  const std::size_t file_buffer_bytes_;
  const io::OutputClaim* claim_;
  std::string fragment_path_;  // write_fragment()
  std::string pending_prefix_ = "pending-";
  bool resumed_ = false;                // the state held an "output" record
  bool points_in_output_ = false;       // the sort merged the points into the partial output
  bool defer_points_order_ = false;     // defer_points_order()
  std::vector<std::uint64_t> pending_;  // the resumed frame, until the cutter takes it
  std::vector<std::uint64_t> held_;     // the resumed brick, until the reorder takes it
  // In this order: the cutter feeds the queue, which feeds the writer, so on the way
  // out of a failure the queue is cancelled and its thread joined before the writer
  // goes.
  std::unique_ptr<io::TetWriter> writer_;
  std::optional<AsyncTetWriter> async_;
  std::optional<FrameCutter> cutter_;
  std::string order_path_;  // the label order's work file (write_label_order)
  std::optional<LabelOrder> order_;
  std::optional<BrickReorder> reorder_;  // feeds the cutter
};

}  // namespace tetstream::pipeline
