// Where a container's tet bytes go (docs/benchmarks.md, "Bytes a tet at scale"): the
// compressed size of each stream of the frame codec (docs/format.md §4.2) per tet, how
// many of each group's upper labels were known from earlier groups of the frame (the
// context, §4.3, remembers those within 65535 labels), the bits a new label's gap
// takes, and how far in labels a tet's upper vertices lie from its smallest.
//
//   build-bench/codec_profile OUT.tets [STRIDE]     (every STRIDE-th frame; default 1)
#include "io/tet_codec.hpp"
#include "io/tet_container.hpp"
#include "io/tet_reader.hpp"
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>
#include <cmath>
#include <cstdio>
#include <unordered_set>
#include <vector>
#include <algorithm>
using namespace tetstream::io;
int main(int argc, char** argv) {
  TetReader r(argv[1]);
  std::uint64_t stride = argc > 2 ? std::stoull(argv[2]) : 1;
  int fd = open(argv[1], O_RDONLY);
  struct stat st;
  fstat(fd, &st);
  auto* base = static_cast<const std::uint8_t*>(mmap(nullptr, st.st_size, PROT_READ, MAP_SHARED, fd, 0));
  double bytes[6] = {}, tets = 0, groups = 0, upper = 0, known = 0, far16 = 0, newbits = 0, nnew = 0;
  std::vector<std::uint64_t> spans;
  std::vector<std::uint64_t> L;
  const char* names[6] = {"HEAD", "ABSN", "GLO", "GHI", "IDX", "PAR"};
  std::uint64_t frames_seen = 0;
  for (std::uint64_t k = 0; k < r.frame_count(); k += stride) {
    const FrameEntry& e = r.frames()[k];
    FrameHeader h;
    std::span<const std::uint8_t> p(base + e.offset + kSectionHeaderSize, e.length);
    if (!parse_frame_header(p, h).empty()) {
      std::puts("bad header");
      return 1;
    }
    for (int s = 0; s < 6; ++s) bytes[s] += h.stream_size[s];
    r.read_frame(k, L);
    ++frames_seen;
    std::unordered_set<std::uint64_t> edges;  // (v<<32|w) seen in earlier groups
    edges.reserve(L.size() * 2);
    std::size_t i = 0, T = L.size() / 4;
    tets += T;
    while (i < T) {
      std::uint64_t m = L[4 * i];
      std::vector<std::uint64_t> U;
      std::size_t j = i;
      for (; j < T && L[4 * j] == m; ++j)
        for (int c = 1; c < 4; ++c) U.push_back(L[4 * j + c]);
      std::sort(U.begin(), U.end());
      U.erase(std::unique(U.begin(), U.end()), U.end());
      groups += 1;
      upper += U.size();
      std::uint64_t prev = m;
      for (auto u : U) {
        bool kn = edges.count((m - e.base_label) << 32 | (u - e.base_label));
        if (kn)
          known += 1;
        else {
          nnew += 1;
          newbits += std::log2(double(u - prev));
          prev = u;
        }
        if (u - m > 65535) far16 += 1;
        spans.push_back(u - m);
      }
      for (std::size_t t = i; t < j; ++t) {
        std::uint64_t v[3] = {L[4 * t + 1], L[4 * t + 2], L[4 * t + 3]};
        std::sort(v, v + 3);
        for (int a = 0; a < 3; ++a)
          for (int b = a + 1; b < 3; ++b) edges.insert((v[a] - e.base_label) << 32 | (v[b] - e.base_label));
      }
      i = j;
    }
  }
  std::sort(spans.begin(), spans.end());
  double tot = 0;
  for (double b : bytes) tot += b;
  std::printf("%s: N=%llu frames %llu of %llu, tets %.0f, frame tets ~%.0f, labels a frame ~%.0f\n", argv[1],
              (unsigned long long)r.point_count(), (unsigned long long)frames_seen, (unsigned long long)r.frame_count(),
              tets, tets / frames_seen, groups / frames_seen);
  std::printf("stream bytes/tet:");
  for (int s = 0; s < 6; ++s) std::printf(" %s %.3f", names[s], bytes[s] / tets);
  std::printf("  total %.3f (+header)\n", tot / tets);
  std::printf("upper labels/group %.2f; known from earlier groups %.1f%%; offset > 65535 %.1f%%\n", upper / groups,
              100 * known / upper, 100 * far16 / upper);
  std::printf(
      "new labels/tet %.3f, mean log2(gap) %.2f bits; label reach u-m: median %llu p90 %llu p99 %llu; N^(2/3) = %.0f\n",
      nnew / tets, newbits / nnew, (unsigned long long)spans[spans.size() / 2],
      (unsigned long long)spans[spans.size() * 9 / 10], (unsigned long long)spans[spans.size() * 99 / 100],
      std::pow(double(r.point_count()), 2.0 / 3));
}
