// Measures the .tets frame codec on tet streams written by cgal_tets (see there):
// bytes per tet, and encode / decode throughput per core, against the baseline of the
// issue (tets sorted by minimum label; the minimum delta-coded, the other three as
// offsets from it; LEB128 varints; zstd -3 over the whole stream), computed in the
// same run on the same tets. Throughput is in MB/s of decoded labels (16 bytes per
// tet) per core: thread CPU time, best of --repeat runs (the machine is shared).
//
// Usage: bench_format [--repeat R] [--frame-tets F] [--cgal-seconds S] [--workdir DIR] NAME=FILE...
#include "io/tet_codec.hpp"
#include "io/tet_reader.hpp"
#include "io/tet_writer.hpp"

#include <zstd.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <string>
#include <vector>

using namespace tetstream::io;

namespace {

using Tet = std::array<std::uint32_t, 4>;

struct Stream {
  std::string name;
  std::vector<std::array<double, 3>> points;
  std::vector<Tet> tets;
};

Stream load(const std::string& name, const std::string& path) {
  Stream s;
  s.name = name;
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) {
    std::perror(path.c_str());
    std::exit(3);
  }
  std::uint64_t head[2];
  bool ok = std::fread(head, sizeof head, 1, f) == 1;
  s.points.resize(head[0]);
  s.tets.resize(head[1]);
  ok = ok && std::fread(s.points.data(), 24, head[0], f) == head[0] &&
       std::fread(s.tets.data(), 16, head[1], f) == head[1];
  std::fclose(f);
  if (!ok) {
    std::fprintf(stderr, "%s: short file\n", path.c_str());
    std::exit(3);
  }
  return s;
}

double cpu_now() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

double wall_now() {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

void put_varint(std::vector<std::uint8_t>& o, std::uint64_t v) {
  while (v >= 0x80) o.push_back(std::uint8_t(v | 0x80)), v >>= 7;
  o.push_back(std::uint8_t(v));
}

std::uint64_t get_varint(const std::uint8_t*& p) {
  std::uint64_t v = 0;
  int shift = 0;
  while (*p & 0x80) v |= std::uint64_t(*p++ & 0x7F) << shift, shift += 7;
  return v | std::uint64_t(*p++) << shift;
}

struct Result {
  std::string codec;
  double bytes_per_tet = 0, encode_s = 1e300, decode_s = 1e300;
};

// The baseline: each tet rotated (even permutation) so its minimum comes first.
Result baseline(const std::vector<Tet>& tets, int repeat) {
  static const int front[4][4] = {{0, 1, 2, 3}, {1, 0, 3, 2}, {2, 3, 0, 1}, {3, 2, 1, 0}};
  Result r{"varint + zstd -3 (baseline)"};
  std::vector<std::uint8_t> raw, z;
  std::vector<Tet> out(tets.size());
  std::vector<std::uint8_t> back;
  for (int rep = 0; rep < repeat; ++rep) {
    double t0 = cpu_now();
    raw.clear();
    std::uint32_t prev = 0;
    for (const Tet& t : tets) {
      const int i = int(std::min_element(t.begin(), t.end()) - t.begin());
      const std::uint32_t m = t[front[i][0]];
      put_varint(raw, m - prev);
      prev = m;
      for (int k = 1; k < 4; ++k) put_varint(raw, t[front[i][k]] - m);
    }
    z.resize(ZSTD_compressBound(raw.size()));
    z.resize(ZSTD_compress(z.data(), z.size(), raw.data(), raw.size(), 3));
    r.encode_s = std::min(r.encode_s, cpu_now() - t0);
    back.resize(raw.size() + 16);
    t0 = cpu_now();
    ZSTD_decompress(back.data(), back.size(), z.data(), z.size());
    const std::uint8_t* p = back.data();
    prev = 0;
    for (Tet& t : out) {
      prev += std::uint32_t(get_varint(p));
      t[0] = prev;
      for (int k = 1; k < 4; ++k) t[k] = prev + std::uint32_t(get_varint(p));
    }
    r.decode_s = std::min(r.decode_s, cpu_now() - t0);
  }
  r.bytes_per_tet = double(z.size()) / double(tets.size());
  return r;
}

// Our codec, frame by frame as the writer does it. Bytes include the section header
// and CRC of every frame, i.e. exactly what the tets cost in a container.
Result ours(const std::vector<Tet>& tets, int level, std::size_t frame_tets, int repeat) {
  Result r{"tets codec, zstd " + std::to_string(level)};
  FrameEncoder enc(level);
  FrameDecoder dec;
  const auto* labels = reinterpret_cast<const std::uint32_t*>(tets.data());
  const auto bounds = frame_boundaries(tets.size(), frame_tets);
  std::vector<EncodedFrame> frames(bounds.size() - 1);
  std::vector<std::uint32_t> out;
  for (int rep = 0; rep < repeat; ++rep) {
    double t0 = cpu_now();
    for (std::size_t f = 0; f + 1 < bounds.size(); ++f) {
      enc.encode(std::span<const std::uint32_t>(labels + 4 * bounds[f], 4 * (bounds[f + 1] - bounds[f])), frames[f]);
    }
    r.encode_s = std::min(r.encode_s, cpu_now() - t0);
    t0 = cpu_now();
    for (const auto& f : frames) dec.decode(f.payload, out);
    r.decode_s = std::min(r.decode_s, cpu_now() - t0);
  }
  std::uint64_t bytes = 0;
  for (const auto& f : frames) bytes += f.payload.size() + 20;
  r.bytes_per_tet = double(bytes) / double(tets.size());
  return r;
}

// Writes and reads a whole container; checks the tets come back.
void container(const Stream& s, const std::string& path, std::size_t frame_tets, double& write_s, double& read_s,
               double& bytes_per_tet) {
  TetFileHeader h;
  h.point_count = s.points.size();
  h.bbox_min = {0, 0, 0};
  h.bbox_max = {1, 1, 1};
  h.tool = "bench_format";
  h.options = "{\"stream\":\"" + s.name + "\"}";
  TetWriterOptions o;
  o.frame_tets = std::uint32_t(frame_tets);
  o.threads = 1;
  double t0 = wall_now();
  {
    TetWriter w(path, h, o);
    w.add_points(&s.points[0][0], nullptr, s.points.size());
    const auto* labels = reinterpret_cast<const std::uint32_t*>(s.tets.data());
    w.add_tets(std::span<const std::uint32_t>(labels, 4 * s.tets.size()));
    w.finish();
  }
  write_s = wall_now() - t0;
  t0 = wall_now();
  TetReader r(path);
  std::vector<std::uint32_t> labels, all;
  all.reserve(4 * s.tets.size());
  for (std::uint64_t k = 0; k < r.frame_count(); ++k) {
    r.read_frame(k, labels);
    all.insert(all.end(), labels.begin(), labels.end());
  }
  read_s = wall_now() - t0;
  bytes_per_tet = double(r.tet_bytes()) / double(r.tet_count());
  // Same set of tets (each canonical: sorted labels plus orientation parity).
  auto key = [](const std::uint32_t* t) {
    std::array<std::uint32_t, 4> v = {t[0], t[1], t[2], t[3]};
    unsigned parity = 0;
    for (int i = 0; i < 4; ++i)
      for (int j = i + 1; j < 4; ++j) parity ^= v[i] > v[j];
    std::sort(v.begin(), v.end());
    return std::array<std::uint32_t, 5>{v[0], v[1], v[2], v[3], parity};
  };
  std::vector<std::array<std::uint32_t, 5>> a, b;
  for (std::size_t i = 0; i < s.tets.size(); ++i)
    a.push_back(key(s.tets[i].data())), b.push_back(key(all.data() + 4 * i));
  std::sort(a.begin(), a.end());
  std::sort(b.begin(), b.end());
  if (a != b) {
    std::fprintf(stderr, "bench_format: %s: the container does not give the tets back\n", s.name.c_str());
    std::exit(1);
  }
  std::remove(path.c_str());
}

}  // namespace

int main(int argc, char** argv) {
  int repeat = 3;
  std::size_t frame_tets = kDefaultFrameTets;
  double cgal_seconds = 0;
  std::string workdir = ".";
  std::vector<std::pair<std::string, std::string>> inputs;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--repeat" && i + 1 < argc)
      repeat = std::atoi(argv[++i]);
    else if (a == "--frame-tets" && i + 1 < argc)
      frame_tets = std::strtoull(argv[++i], nullptr, 10);
    else if (a == "--cgal-seconds" && i + 1 < argc)
      cgal_seconds = std::atof(argv[++i]);
    else if (a == "--workdir" && i + 1 < argc)
      workdir = argv[++i];
    else if (a.find('=') != std::string::npos)
      inputs.emplace_back(a.substr(0, a.find('=')), a.substr(a.find('=') + 1));
    else {
      std::fprintf(stderr, "usage: %s [--repeat R] [--frame-tets F] [--cgal-seconds S] [--workdir DIR] NAME=FILE...\n",
                   argv[0]);
      return 2;
    }
  }
  std::printf(
      "frames of at most %zu tets; throughput = MB/s of decoded 32-bit labels (16 B/tet) per core, "
      "best of %d; zstd %s\n\n",
      frame_tets, repeat, ZSTD_versionString());
  std::printf("| label order | codec | bytes/tet | encode MB/s | decode MB/s | encode ns/tet | encode CPU / CGAL |\n");
  std::printf("|---|---|---|---|---|---|---|\n");
  std::vector<std::string> container_lines;
  for (const auto& [name, path] : inputs) {
    const Stream s = load(name, path);
    const double n = double(s.tets.size());
    std::vector<Result> results = {baseline(s.tets, repeat), ours(s.tets, 1, frame_tets, repeat),
                                   ours(s.tets, 3, frame_tets, repeat)};
    for (const Result& r : results) {
      char ratio[32] = "-";
      if (cgal_seconds > 0) std::snprintf(ratio, sizeof ratio, "%.1f%%", 100.0 * r.encode_s / cgal_seconds);
      std::printf("| %s | %s | %.3f | %.0f | %.0f | %.1f | %s |\n", name.c_str(), r.codec.c_str(), r.bytes_per_tet,
                  16.0 * n / r.encode_s / 1e6, 16.0 * n / r.decode_s / 1e6, 1e9 * r.encode_s / n, ratio);
      std::fflush(stdout);
    }
    double write_s, read_s, bpt;
    container(s, workdir + "/bench_" + name + ".tets", frame_tets, write_s, read_s, bpt);
    char line[256];
    std::snprintf(
        line, sizeof line,
        "%s: container of %zu points (float64) and %zu tets: %.3f bytes/tet, write %.2f s, read %.2f s (wall)",
        name.c_str(), s.points.size(), s.tets.size(), bpt, write_s, read_s);
    container_lines.push_back(line);
  }
  std::printf("\n");
  for (const auto& l : container_lines) std::printf("%s\n", l.c_str());
  if (cgal_seconds > 0) {
    std::printf("CGAL Delaunay_triangulation_3 on the same points: %.2f CPU s (the last column compares with it)\n",
                cgal_seconds);
  }
  return 0;
}
