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
// Neighbours: each batch's edges are packed, radix-sorted and made unique, and handed
// out at once; the caller's external sort by original index makes them unique overall.
#include "io/tet_reader.hpp"
#include "pipeline/field_window.hpp"

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
  bool hull = false;     // on the convex hull (solid angles sum below 3 pi)
};

struct AccumulateSinks {
  bool voronoi = true;  // compute the Voronoi sums (FinalPoint::voronoi is 0 otherwise)
  std::function<void(const FinalPoint&)> point;
  // Set to collect neighbours: each Delaunay edge as the original indices of its
  // endpoints, at least once (once per batch whose tets hold it).
  std::function<void(std::uint64_t, std::uint64_t)> edge;
};

struct AccumulateStats {
  std::uint64_t tets = 0, batches = 0;
  std::uint64_t batch_edges = 0;        // edges handed out (copies across batches included)
  std::uint64_t peak_far = 0;           // most far labels held (field_points.hpp)
};

AccumulateStats accumulate_fields(const io::TetReader& reader, const BatchPlan& plan, const AccumulateSinks& sinks,
                                  Progress* progress);

// The solid-angle sum below which a point is on the hull (see field_geometry.hpp).
inline constexpr double kHullAngleThreshold = 3.0 * 3.14159265358979323846;

}  // namespace tetstream::pipeline
