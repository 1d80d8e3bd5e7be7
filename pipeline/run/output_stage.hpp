#pragma once
// The stage that takes the triangulation's segments and makes the job's output, as
// Job::run (run.cpp) drives it: the write stage (stage_write.hpp: the container of
// these points' tets), or a periodic job's keep (pipeline/periodic/keep_stage.hpp: the
// padded job's tets kept, certified and written as the periodic container). Its
// record in the checkpoint is its own, and so is the label the triangulation resumes
// from: the labels below it are in the output.
#include "pipeline/run/stage_triangulate.hpp"

#include "pipeline/util/stage_time.hpp"

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace tetstream::pipeline {

// The work of the segments written so far, this process's and earlier ones': the
// record's "counters", so that a resumed job's summary describes the whole job.
struct WrittenWork {
  SegmentStats stats;
  std::uint64_t segment_labels = 0;  // labels of the segments written (checkpoint key "zone_points")
};

class OutputStage : public SegmentSink {
 public:
  virtual ~OutputStage() = default;
  // Opens the output, new or resumed from the stage's record.
  virtual void prepare() = 0;
  // Starts what runs beside the triangulation (the writer's thread, the points).
  virtual void run() = 0;
  // Every tet of the labels below `end_label` (all of them by default) is in.
  virtual void commit(std::uint64_t end_label = ~std::uint64_t(0)) = 0;
  // The output complete and in place. Nothing may follow it.
  virtual void finish() = 0;

  // From the record prepare read: the label the triangulation goes on from, and the
  // segments an earlier process wrote; the segments written and their work so far.
  std::uint64_t first_label() const { return first_label_; }
  std::uint64_t segments_resumed() const { return segments_resumed_; }
  std::uint64_t segments_done() const { return segments_done_; }
  const WrittenWork& work() const { return work_; }
  // The triangulation waiting on this stage (merges, records, a full queue) and the
  // commit and finish: the summary's seconds_write. Then its seconds_writer_busy,
  // seconds_writer_wait, output_bytes, tet_bytes.
  double seconds() const { return seconds_; }
  virtual double busy_seconds() const = 0;
  virtual double producer_wait_seconds() const = 0;
  virtual std::uint64_t bytes_written() const = 0;
  virtual std::uint64_t tet_bytes() const = 0;
  // Phases of its own, timed, for the summary's stages (the write stage's
  // "write.label_order" and "write.points_order" with version 2's labels).
  const std::vector<std::pair<std::string, StageTime>>& phases() const { return phases_; }

 protected:
  std::vector<std::pair<std::string, StageTime>> phases_;
  std::uint64_t first_label_ = 0, segments_resumed_ = 0, segments_done_ = 0;
  WrittenWork work_;
  double seconds_ = 0;
};

}  // namespace tetstream::pipeline
