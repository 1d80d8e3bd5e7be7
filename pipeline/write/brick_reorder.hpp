#pragma once
// Between the segments' merged tets and the frames: the tets in format 2's labels
// (pipeline/write/label_order.hpp), a brick at a time in order of their new smallest
// label.
//
// The segments' tets come in increasing smallest *sorted* label, and a brick maps its
// labels onto themselves, so they come brick by brick: the tets of a brick are complete
// once a tet of a later brick arrives, or once the segments have passed its end
// (done_below). Then they are put in order of their smallest new label (a stable radix
// sort of the tets themselves, a pass or two: gathering them one by one in that order
// missed the cache at every tet) and handed to the frame cutter. What is held is the
// brick being filled: about 7 tets a label of one brick, 4-byte labels when the job's
// fit in 32 bits (bytes_for).
#include "pipeline/window/zone_triangulator.hpp"
#include "pipeline/write/frame_cutter.hpp"
#include "pipeline/write/label_order.hpp"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace tetstream::pipeline {

class BrickReorder {
 public:
  BrickReorder(FrameCutter& cutter, LabelOrder& order);

  // The tets [begin, end) of a zone's output, in sorted labels, after every tet of a
  // smaller smallest label (merge_by_min_label's order).
  void add(const ZoneTets& part, std::size_t begin, std::size_t end);
  // Every tet whose smallest sorted label is below `label` has been added: the bricks
  // that end at or below it go to the cutter.
  void done_below(std::uint64_t label);
  // The tets held (the brick not complete), 4 format 2 labels each: a checkpoint saves
  // them, a resumed job restores them, and its frames come out as an uninterrupted
  // job's.
  std::vector<std::uint64_t> held() const;
  void restore(const std::vector<std::uint64_t>& held);
  std::size_t held_tets() const { return tets(); }

  // The most this holds for bricks of `brick` labels (a label has ~6.8 tets; 7.5 is
  // above every input measured), with labels of 4 bytes or 8 (`wide`).
  static std::uint64_t bytes_for(std::uint64_t brick, bool wide);
  // With the label order's kept bricks, for a job of `points` points.
  static std::uint64_t job_bytes(std::uint64_t points);

 private:
  // A tet held: its format 2 labels and its smallest one less the brick's first.
  template <class L>
  struct Held {
    L label[4];
    std::uint32_t min;
  };
  template <class L>
  void emit(std::vector<Held<L>>& held, std::vector<Held<L>>& scratch);
  void start_brick(std::uint64_t b);  // the brick held from now on (the one before emitted)
  void emit();                        // the brick held, in order, to the cutter
  std::size_t tets() const { return wide_ ? held64_.size() : held32_.size(); }
  void push(const std::uint64_t* q, std::uint64_t m);

  FrameCutter& cutter_;
  LabelOrder& order_;
  const bool wide_;                          // labels past 2^32
  std::uint64_t brick_ = ~std::uint64_t(0);  // the brick held, by index
  std::uint64_t base_ = 0, span_ = 0;        // its first label and its labels
  std::vector<Held<std::uint32_t>> held32_, scratch32_;
  std::vector<Held<std::uint64_t>> held64_, scratch64_;
  std::vector<std::size_t> count_;  // the radix sort's buckets
};

}  // namespace tetstream::pipeline
