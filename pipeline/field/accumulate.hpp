#pragma once
// Pass 1 of `tetstream field`: streams the container's frames once, batch by batch
// (pipeline/field_window.hpp), sums each tet's contributions (field_geometry.hpp) into
// per-label accumulators that live in a ring over the window, and hands every point to
// the caller once it is final, in label order.
//
// Determinism: frames are decoded and the per-tet geometry computed on all OpenMP
// threads, but the sums are made by one thread in a fixed order (frame, then tet in
// stored order, then vertex), so every point's sums are the same bits whatever the
// thread count and whatever the batching (the memory budget).
//
// Neighbours: each batch's edges are packed, radix-sorted and made unique, and kept as
// directed (label, neighbour's original index) entries until their label retires; a
// retiring point's entries (from every batch that touched it) are sorted and made
// unique into its row, handed out once.
#include "io/tet_reader.hpp"
#include "pipeline/field/window.hpp"

#include <cstdint>
#include <functional>
#include <span>

namespace tetstream::pipeline {

class Progress;

// A final point, in label order.
struct FinalPoint {
  std::uint64_t label = 0, original = 0;
  double xyz[3];
  double volume = 0.0;   // sum of the incident tets' volumes
  double voronoi = 0.0;  // sum of the Voronoi pieces (the cell's volume when interior)
  bool hull = false;     // on the convex hull's boundary (its hull terms do not cancel)
};

struct AccumulateSinks {
  bool voronoi = true;  // compute the Voronoi sums (FinalPoint::voronoi is 0 otherwise)
  // false (only with `row`): no hull terms (field_geometry.hpp); the hull flag comes
  // from the rows instead. A point's link (the triangles opposite it in its T tets, on
  // its d neighbours) is a triangulated sphere when the point is interior, so T = 2 d - 4
  // (Euler: d - 3T/2 + T = 2), and a disk with b >= 3 boundary edges when it is on the
  // hull, so T = 2 d - 2 - b < 2 d - 4. `--neighbours` alone then computes only the
  // volumes (for `hull_volume`), in the edges' loop.
  bool hull_terms = true;
  // The points a batch retires, in label order (the span is valid during the call only).
  std::function<void(std::span<const FinalPoint>)> points;
  // Set to collect neighbours: called once per point, in label order, when it retires,
  // with its original index and its Delaunay neighbours' original indices (increasing,
  // no repeats; the span is valid during the call only).
  std::function<void(std::uint64_t, std::span<const std::uint32_t>)> row;
};

struct AccumulateStats {
  std::uint64_t tets = 0, batches = 0;
  std::uint64_t batch_edges = 0;      // unique edges per batch, summed (copies across batches included)
  std::uint64_t batch_edge_keys = 0;  // edges sorted (before the unique): what the repeat filter left
  std::uint64_t peak_far = 0;         // most far labels held (field_points.hpp)
};

AccumulateStats accumulate_fields(const io::TetReader& reader, const BatchPlan& plan, const AccumulateSinks& sinks,
                                  Progress* progress);

}  // namespace tetstream::pipeline
