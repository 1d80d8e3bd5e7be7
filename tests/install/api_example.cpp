// docs/cpp.md's example, built by tests/install/install_test.sh against the installed
// package exactly as the page shows (find_package(tetstream), no C++ standard of its
// own): reads a container, triangulates its points in memory, runs the out-of-core job
// on a point file, and checks that all three agree.
// Usage: api_example POINTS.f64 OUT.tets
#include <tetstream/tetstream.hpp>

#include <algorithm>
#include <array>
#include <cstdio>
#include <set>

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: api_example POINTS.f64 OUT.tets\n");
    return 2;
  }
  try {
    // Out of core: a point file to a container, within a memory budget.
    tetstream::RunOptions options;
    options.inputs = {argv[1]};
    options.output = argv[2];
    options.memory_bytes = std::uint64_t(256) << 20;
    options.checkpoint = false;
    const tetstream::RunSummary summary = tetstream::run(options);

    // Read the container back: its points (by label) and their input indices.
    const tetstream::Container container(argv[2]);
    const std::uint64_t n = container.point_count();
    const std::vector<double> xyz = container.points(0, n);
    const std::vector<std::uint64_t> ids = container.original_ids(0, n);

    // In memory: the same points, the same tets (as sets of input indices).
    const tetstream::Triangulation t = tetstream::triangulate(xyz);
    std::set<std::array<std::uint64_t, 4>> in_memory, from_file;
    for (std::size_t i = 0; i < t.size(); ++i) {
      std::array<std::uint64_t, 4> v;
      for (int j = 0; j < 4; ++j) v[j] = ids[std::size_t(t.simplices[4 * i + j])];
      std::sort(v.begin(), v.end());
      in_memory.insert(v);
    }
    for (std::uint64_t k = 0; k < container.frame_count(); ++k) {
      const std::vector<std::uint64_t> tets = container.frame(k, /*original_ids=*/true);
      for (std::size_t i = 0; i < tets.size(); i += 4) {
        std::array<std::uint64_t, 4> v{tets[i], tets[i + 1], tets[i + 2], tets[i + 3]};
        std::sort(v.begin(), v.end());
        from_file.insert(v);
      }
    }
    std::printf("%llu points, %llu tets out of core, %zu in memory, %s\n",
                static_cast<unsigned long long>(summary.points), static_cast<unsigned long long>(summary.tets),
                t.size(), in_memory == from_file ? "the same" : "DIFFERENT");
    return in_memory == from_file && summary.tets == container.tet_count() ? 0 : 1;
  } catch (const tetstream::Error& e) {
    std::fprintf(stderr, "api_example: %s\n", e.what());
    return 1;
  }
}
