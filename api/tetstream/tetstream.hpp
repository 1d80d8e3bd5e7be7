#pragma once
// tetstream's public C++ API (docs/cpp.md): the three things a program linking the
// library does, with the conventions of the Python package, behind one header and no
// internal types:
//
//   tetstream::Triangulation t = tetstream::triangulate(xyz);      // in memory, exact
//   tetstream::RunSummary s = tetstream::run(options);             // out of core, to a .tets
//   tetstream::Container c("out.tets");                             // read a container
//
// Errors are exceptions derived from tetstream::Error (a std::runtime_error with an
// exit code): InputError (bad data), UsageError (bad options), IoError (the system).
// Installed as include/tetstream/tetstream.hpp: #include <tetstream/tetstream.hpp> with
// the CMake target tetstream::tetstream (find_package(tetstream)).
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace tetstream {

// The error types (the same classes as the library's own, core/error.hpp).
enum class ExitCode : int;
class Error;
class InputError;
class UsageError;
class IoError;

// ---- in memory ----

// The Delaunay triangulation of points in memory, as tetstream.delaunay() returns it.
struct Triangulation {
  // 4 per tet: indices into the caller's points, positively oriented
  // (det[p1 - p0, p2 - p0, p3 - p0] > 0).
  std::vector<std::int64_t> simplices;
  // 4 per tet: neighbors[4 t + j] is the tet across the facet opposite vertex j of tet
  // t, or -1 on the convex hull.
  std::vector<std::int64_t> neighbors;
  // 2 per exact duplicate: [i, j], input point i merged into j, the first of its copies
  // (j < i), which is the vertex. Sorted by i.
  std::vector<std::int64_t> duplicates;

  std::size_t size() const { return simplices.size() / 4; }
};

// Triangulates n points given as 3 n doubles (x, y, z each), exactly: every predicate
// is evaluated exactly and degenerate inputs are resolved by one symbolic perturbation
// keyed by the input index. At most about 1.5e8 points (use run() beyond). Throws
// InputError for a non-finite coordinate or fewer than 4 affinely independent points.
// `threads` (0: all cores) convert the result; the insertion itself is sequential.
Triangulation triangulate(std::span<const double> xyz, int threads = 0);

// ---- out of core ----

// `tetstream run` as a struct: the inputs are read in order as one input (point files:
// raw .f64/.f32, PLY, .npy, text, LAS, HDF5; docs/inputs.md).
struct RunOptions {
  std::vector<std::string> inputs;
  std::string output;  // the .tets container
  std::uint64_t memory_bytes = std::uint64_t(1) << 30;
  int threads = 0;                    // 0: all cores
  std::string tmpdir;                 // empty: the output's directory
  bool checkpoint = true;             // resumable (OUTPUT.ckpt)
  bool resume = false;                // continue a checkpointed job
  bool force = false;                 // discard a checkpoint and start over
  bool progress = false;              // the job's info lines through spdlog (else warnings only)
  std::vector<std::string> datasets;  // HDF5: the (N, 3) datasets to read
};

struct RunSummary {
  std::uint64_t input_points = 0, points = 0, duplicates = 0;
  std::uint64_t tets = 0, segments = 0, zones = 0, output_bytes = 0;
  double seconds = 0;
  bool resumed = false;
};

// Triangulates out of core within options.memory_bytes; the same bytes as the CLI.
RunSummary run(const RunOptions& options);

// ---- a container ----

// A .tets container opened for reading (memory-mapped, checked; each frame's checksum
// when it is read). Points are in the container's order ("labels"); original ids are
// their indices in the job's input.
class Container {
 public:
  explicit Container(const std::string& path);
  ~Container();
  Container(Container&&) noexcept;
  Container& operator=(Container&&) noexcept;

  std::uint64_t point_count() const;
  std::uint64_t input_count() const;  // before exact duplicates were merged
  std::uint64_t tet_count() const;
  std::uint64_t frame_count() const;

  // Points [first, first + count): 3 doubles each, and their original ids.
  std::vector<double> points(std::uint64_t first, std::uint64_t count) const;
  std::vector<std::uint64_t> original_ids(std::uint64_t first, std::uint64_t count) const;
  // Frame k's tets, 4 labels each (or original ids), positively oriented.
  std::vector<std::uint64_t> frame(std::uint64_t k, bool original_ids = false) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tetstream

#include "core/error.hpp"  // the error classes declared above
