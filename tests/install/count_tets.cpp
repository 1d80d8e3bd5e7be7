// Prints the number of tetrahedra in a .tets container, read with io::TetReader from
// the installed headers and libraries (tests/install/install_test.sh).
#include "core/error.hpp"
#include "io/tet_reader.hpp"

#include <cstdio>
#include <vector>

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: count_tets FILE.tets\n");
    return 2;
  }
  try {
    const tetstream::io::TetReader reader(argv[1]);
    // Read every frame too, so the codec is linked and exercised, not only the footer.
    std::uint64_t read = 0;
    std::vector<std::uint64_t> labels;
    for (std::uint64_t k = 0; k < reader.frame_count(); ++k) {
      reader.read_frame(k, labels);
      read += labels.size() / 4;
    }
    if (read != reader.tet_count()) {
      std::fprintf(stderr, "count_tets: frames hold %llu tets, the footer says %llu\n",
                   static_cast<unsigned long long>(read), static_cast<unsigned long long>(reader.tet_count()));
      return 1;
    }
    std::printf("%llu\n", static_cast<unsigned long long>(reader.tet_count()));
  } catch (const tetstream::Error& e) {
    std::fprintf(stderr, "count_tets: %s\n", e.what());
    return 1;
  }
  return 0;
}
