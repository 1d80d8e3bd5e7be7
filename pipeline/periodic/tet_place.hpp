#pragma once
// Exact coordinates for a few points of a periodic container given as labels and
// offsets in periods (docs/periodic.md, "Exact images"): on each axis the offsets are
// shifted into {-1, 0} (points of one tet and its neighbour span at most two
// consecutive values: they are closer than a period), and an offset -1 places the
// point at x - L, computed exactly or refused (for x >= L/2 it is always exact,
// Sterbenz). With exact coordinates, the exact predicates answer for the real
// configuration; `rank` gives the symbolic perturbation the job used: the points'
// lexicographic order from the container's sort axis, which a translation keeps.
#include "io/tet_periodic.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/periodic/pad.hpp"

#include <algorithm>
#include <cstdint>

namespace tetstream::pipeline::periodic {

struct Placed {
  double xyz[5][3];
  std::uint64_t rank[5];
};

inline bool place(const io::TetReader& r, const io::PeriodicBox& box, const std::uint64_t* label, const int (*off)[3],
                  int n, Placed& out) {
  double p[5][3];
  for (int i = 0; i < n; ++i) r.read_points(label[i], 1, p[i], nullptr);
  for (int k = 0; k < 3; ++k) {
    int lo = 1, hi = -1;
    for (int i = 0; i < n; ++i) lo = std::min(lo, off[i][k]), hi = std::max(hi, off[i][k]);
    if (hi - lo > 1) return false;
    for (int i = 0; i < n; ++i) {
      if (off[i][k] == hi) {
        out.xyz[i][k] = p[i][k];
      } else if (!exact_difference(p[i][k], box.period[k], out.xyz[i][k])) {
        return false;
      }
    }
  }
  for (int i = 0; i < n; ++i) {
    out.rank[i] = 0;
    for (int j = 0; j < n; ++j) {
      for (int c = 0; c < 3; ++c) {
        const int a = (box.sort_axis + c) % 3;
        if (out.xyz[j][a] != out.xyz[i][a]) {
          out.rank[i] += out.xyz[j][a] < out.xyz[i][a];
          break;
        }
      }
    }
  }
  return true;
}

}  // namespace tetstream::pipeline::periodic
