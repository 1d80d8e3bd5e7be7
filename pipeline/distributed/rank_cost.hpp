#pragma once
// What a range of labels is expected to cost to triangulate, for dividing a job's
// labels between the ranks of a distributed run (pipeline/run_distributed.cpp).
//
// Points alone are a poor measure: on a surface (a LiDAR terrain, plates, a shell)
// a point costs several times what a uniform point does, because its tets are flat
// and their circumballs huge, so most fail the range test and need emptiness queries
// (docs/benchmarks.md, issue 18). A half-terrain, half-uniform set split by points
// gave the terrain's rank 3.5 times the other's triangulation time.
//
// The estimate looks at that cause directly: in each block of the point index, a
// pilot triangulation of two spatially compact samples (about 2048 points each) counts
// the share f of its inner tets whose circumradius exceeds 8 times the median. On
// uniform and clustered points f is about 0.01; on the terrain 0.17.
// A point then costs 1 + kFlatTetWeight * f.
#include "pipeline/window/point_index.hpp"

#include <cstdint>
#include <vector>

namespace tetstream::pipeline {

// The cost of labels [first, last) in blocks of `unit` labels: element i covers labels
// [first + i * unit, first + (i + 1) * unit) (the last one may be shorter), each label
// costing its index block's factor (block_cost_factor). Deterministic: every rank
// computes the same figures from the same index and points.
std::vector<double> expected_cost(const PointIndex& index, const PointRecords& points, std::uint64_t first,
                                  std::uint64_t last, std::uint64_t unit);

// 1 + kFlatTetWeight * f for index block b (see above); 1 when a sample is too small
// or too flat to triangulate.
double block_cost_factor(const PointIndex& index, const PointRecords& points, std::uint64_t b);

// What a tet whose ball is huge beside its neighbours' adds to its point's cost, in
// points: calibrated so that a terrain point costs about what the ranks measure
// against a uniform one (run_distributed's debug log prints each block's cost). The
// true factor grows as zones shrink and the estimate does not model zones: the
// weight is a compromise.
inline constexpr double kFlatTetWeight = 12.0;

// The label ranges of `ranks` ranks over `count` labels: contiguous runs of whole
// blocks of `block` labels, balanced by the blocks' `costs` (one a block; empty: by
// points), each rank's range ending at the block boundary nearest its share of the
// cost; bounds[r] to bounds[r + 1] is rank r's (empty when there are fewer
// blocks than ranks). `rank0_done`: the labels rank 0 has written already (a resumed
// job's record, maybe from another number of ranks): when they reach past its share,
// its range ends at the block that holds their end and the other ranks share the rest.
std::vector<std::uint64_t> rank_label_bounds(std::uint64_t count, std::uint64_t block, int ranks,
                                             std::uint64_t rank0_done = 0,
                                             const std::vector<std::uint64_t>& costs = {});

}  // namespace tetstream::pipeline
