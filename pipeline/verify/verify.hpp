#pragma once
// `tetstream verify`: an independent, out-of-core certificate that a container holds
// the Delaunay triangulation of its points (docs/verify.md).
//
// It trusts nothing but the exact predicates of core/predicates.hpp and the points'
// labels (their positions in the container's point order, which drive the symbolic
// perturbation). What it proves, when every check passes:
//
//   storage      every tet has 4 distinct labels < N;
//   orientation  every tet is positively oriented (exact orient3d > 0);
//   pairing      every facet (triangle) lies in exactly two tets, on opposite sides of
//                it, or in one tet (a boundary facet); no tet appears twice;
//   delaunay     every facet of two tets is locally Delaunay: the perturbed insphere of
//                one tet rejects the other's opposite vertex;
//   hull         the boundary facets form a closed, consistently oriented surface with
//                V - E + F = 2, locally convex at every edge (exact orient3d; on
//                coplanar facets the perturbed in-circle test the kernel uses);
//   coverage     every label 0..N-1 is a vertex;
//   euler        V - E + F - T = 1 for the whole complex (edges counted exactly);
//   volume       the summed tet volume equals the volume the boundary encloses
//                (divergence theorem), to a relative tolerance.
// Oriented pairing plus a closed convex boundary make the tets a triangulation of the
// convex hull (the volume and Euler checks confirm it covers it once); local Delaunay
// on every facet then makes it globally Delaunay (the Delaunay lemma, for the lifted,
// perturbed points), i.e. the one triangulation the kernel's perturbation defines.
//
// Out of core: tets stream batch by batch (container frames). Facets and edges are
// keyed by their smallest label; a batch whose labels are all >= L promises that no
// later tet touches a key below L (the container's frame index records each frame's
// smallest label), so keys below the smallest label of the batches still to come are
// final and leave memory. Keys still open when their budget is exhausted spill to an
// external sort (pipeline/external_sort.hpp) in `tmpdir` and are matched at the end.
// Outputs written in label order (tetstream's own) keep only a thin front of open
// facets in memory; any order is correct, just slower.
//
// Memory: 12 or 24 bytes per point (coordinates as floats for a float32 container, else
// doubles; random access by label), 2 bits
// per point (vertex and hull-vertex bitmaps), a batch of scratch, and the open facets
// and edges up to the budget; beyond that, disk.
#include "pipeline/util/communicator.hpp"

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace tetstream::io {
class TetReader;
}

namespace tetstream::pipeline {

enum class Violation : int {
  kStorage,        // a label >= N or repeated in a tet
  kOrientation,    // orient3d <= 0
  kDuplicateTet,   // the same four labels twice (counted once per extra copy)
  kFacetOverused,  // a facet in three or more tets (not copies of one tet)
  kFacetSameSide,  // two tets on the same side of their common facet (overlap)
  kDelaunay,       // a facet of two tets not locally Delaunay
  kHullOpen,       // a boundary edge not in exactly two boundary facets of opposite directions
  kHullConvex,     // a boundary edge where the surface is not convex (a hole, a missing tet)
  kHullTopology,   // boundary V - E + F != 2 (several surfaces: a cavity, a loose piece)
  kMissingPoint,   // a label in no tet
  kEuler,          // V - E + F - T != 1
  kVolume,         // tet volume != volume enclosed by the boundary
  kCount
};
inline constexpr int kViolationKinds = static_cast<int>(Violation::kCount);
const char* violation_name(Violation v);  // "orientation", "duplicate_tet", ...

struct VerifyOptions {
  std::uint64_t memory_bytes = std::uint64_t(1) << 30;
  std::string tmpdir;              // for spills; empty: $TMPDIR, else the output's directory, else "."
  double sample = 1.0;             // (0, 1]: below 1, the quick look of docs/verify.md
  std::uint64_t seed = 1;          // of the sample
  double volume_tolerance = 1e-9;  // relative
  std::size_t max_listed = 10;     // violations described, per kind (all are counted)
  // Tets per processing step, at most (a frame is split into steps; a small --memory
  // takes smaller ones). Each step merges the open facets and edges once, and they grow
  // as N^(2/3), so steps of a whole frame of `run`'s output (2^18 tets) keep that merge
  // a small share at 10^9 (docs/verify.md, "Speed").
  std::size_t batch_tets = std::size_t(1) << 18;
  bool progress = true;
  bool wide_labels = false;    // the 64-bit label path even when labels fit 32 bits (tests)
  std::size_t open_bytes = 0;  // cap on the open facets (edges: a third); 0: from memory_bytes (tests force spills)

  void validate() const;  // throws UsageError
};

struct VerifyReport {
  bool sampled = false;  // sample < 1: only the checks of the quick look ran
  double sample = 1.0;
  std::uint64_t points = 0;    // N
  std::uint64_t tets = 0;      // T, as stored
  std::uint64_t vertices = 0;  // distinct labels used
  std::uint64_t facets = 0;    // distinct triangles (interior + boundary + bad)
  std::uint64_t interior_facets = 0, boundary_facets = 0;
  std::uint64_t edges = 0;  // distinct
  std::uint64_t hull_vertices = 0, hull_edges = 0;
  std::int64_t euler = 0;       // V - E + F - T
  std::int64_t hull_euler = 0;  // of the boundary surface
  double tet_volume = 0, hull_volume = 0, volume_rel_error = 0;

  // Work done.
  std::uint64_t orient_tests = 0, insphere_tests = 0, hull_tests = 0;
  std::uint64_t tets_checked = 0, facets_checked = 0;  // differ from the totals when sampled

  // Resources.
  std::uint64_t peak_open_facets = 0, peak_open_edges = 0;
  std::uint64_t spilled_records = 0, spill_bytes = 0;
  std::uint64_t memory_planned = 0;  // bytes of the big arrays at their peak (estimate)
  std::uint64_t step_tets = 0;       // tets a processing step (planned from --memory)
  double seconds = 0;

  std::array<std::uint64_t, kViolationKinds> counts{};
  struct Listed {
    Violation kind;
    std::uint64_t where;  // tet ordinal (label for missing points)
    std::string text;
  };
  std::vector<Listed> listed;  // the first violations of each kind, by kind then ordinal

  std::uint64_t violations() const;
  bool ok() const { return violations() == 0; }
  // A few lines: verdict, counts, checks; then the listed violations.
  std::string summary() const;
};

// Where verify() reads from: the points by label and the tets in batches. The
// container adapter is ContainerSource; tests feed memory.
class VerifySource {
 public:
  struct Batch {
    std::uint64_t first_tet = 0;  // ordinal of its first tet
    std::uint64_t tet_count = 0;
    std::uint64_t min_label = 0;      // a lower bound of its labels (0 when unknown)
    std::uint64_t max_label = ~0ull;  // an upper bound of its labels (~0 when unknown)
  };
  virtual ~VerifySource() = default;
  virtual std::uint64_t point_count() const = 0;
  virtual std::uint64_t tet_count() const = 0;
  virtual std::size_t batch_count() const = 0;
  virtual Batch batch(std::size_t k) const = 0;
  // The points where they lie, read by label in place (not copied: a copy of 10^9
  // float32 points is 12 GB, more than an 8G budget): record l at base + l * stride,
  // three coordinates first, as floats or as doubles. Valid while the source lives.
  struct PointRecords {
    const std::uint8_t* base = nullptr;
    std::size_t stride = 0;
    bool floats = false;
  };
  virtual PointRecords points() const = 0;
  // Hands the memory of the points [first, first + n) back where the source can (a
  // mapped file's pages: later reads fault them in again), so that a pass that reads a
  // window of labels at a time keeps a window of them resident.
  virtual void release_points(std::uint64_t /*first*/, std::uint64_t /*n*/) const {}
  // Batch k, 4 labels per tet in stored order. May be called from several threads at
  // once for different k.
  virtual void read_batch(std::size_t k, std::vector<std::uint32_t>& labels) const = 0;
  virtual void read_batch(std::size_t k, std::vector<std::uint64_t>& labels) const = 0;
  virtual std::string name() const = 0;                 // for messages
  virtual std::string directory() const { return {}; }  // default tmpdir
  // The order of the symbolic perturbation (docs/format.md §3.4): -1 when it is the
  // labels' (format 1, and memory); else the axis the points were sorted along, whose
  // order (their coordinates compared from that axis on) the labels of format 2 no
  // longer follow.
  virtual int sort_axis() const { return -1; }
};

// Points and tets held in memory (tests, tools that triangulate in core).
class MemorySource : public VerifySource {
 public:
  // xyz: 3 per point; tets: 4 labels per tet; batches of batch_tets tets, each
  // declaring its smallest label.
  MemorySource(std::vector<double> xyz, std::vector<std::uint64_t> tets, std::size_t batch_tets = 1 << 16);
  std::uint64_t point_count() const override { return xyz_.size() / 3; }
  std::uint64_t tet_count() const override { return tets_.size() / 4; }
  std::size_t batch_count() const override { return batches_.size(); }
  Batch batch(std::size_t k) const override { return batches_[k]; }
  PointRecords points() const override;
  void read_batch(std::size_t k, std::vector<std::uint32_t>& labels) const override;
  void read_batch(std::size_t k, std::vector<std::uint64_t>& labels) const override;
  std::string name() const override { return "memory"; }

 private:
  std::vector<double> xyz_;
  std::vector<std::uint64_t> tets_;
  std::vector<Batch> batches_;
};

// A .tets container: frames are the batches, the frame index gives their smallest label.
class ContainerSource : public VerifySource {
 public:
  explicit ContainerSource(const io::TetReader& reader);
  std::uint64_t point_count() const override;
  std::uint64_t tet_count() const override;
  std::size_t batch_count() const override;
  Batch batch(std::size_t k) const override;
  PointRecords points() const override;  // the mapped PNTS records
  void release_points(std::uint64_t first, std::uint64_t n) const override;
  void read_batch(std::size_t k, std::vector<std::uint32_t>& labels) const override;
  void read_batch(std::size_t k, std::vector<std::uint64_t>& labels) const override;
  std::string name() const override;
  std::string directory() const override;
  int sort_axis() const override;

 private:
  const io::TetReader& reader_;
};

// Runs every check (or the sample's). Violations are results, not exceptions;
// exceptions are for unreadable input (InputError) and I/O failures (IoError).
//
// On the ranks of a job (every rank calls it, with the same source and options): rank
// r checks about a K-th of the tets, the frames whose smallest labels fall in its
// label range (pipeline/verify/split.hpp), and finalizes the facets and edges keyed
// in that range; the records an earlier rank's tets make for them are handed over
// first (pipeline/verify/ranks.ipp). Rank 0's report is the job's: the same counts,
// violations, volumes and verdict as one process (single_process(), the run of rank 0
// of 1), apart from the resource figures (peaks: the largest rank's; spills: summed).
// The other ranks' reports carry the verdict (counts) only. A failure on any rank
// stops every rank (together(), pipeline/communicator.hpp).
VerifyReport verify(const VerifySource& source, const VerifyOptions& options, Communicator& comm = single_process());
// Opens the container (on every rank) and verifies it.
VerifyReport verify_file(const std::string& path, const VerifyOptions& options, Communicator& comm = single_process());

}  // namespace tetstream::pipeline
