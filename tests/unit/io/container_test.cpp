// The .tets container: CRC, frame codec, writer, reader, damaged files, resume, and the
// golden files that pin the format (tests/data/golden_v*.golden, docs/format.md).
//
// Tets are synthetic (the kernel is tested elsewhere): a lattice of cubes, each split
// into the 6 tets of the Kuhn triangulation along its main diagonal, oriented
// positively with an exact integer determinant. Failing randomized tests print
// their seed.
//
// Regenerating the golden files (only after a deliberate format change, or when a new
// zstd release compresses the same bytes differently; the reader checks still pass):
//   TETSTREAM_UPDATE_GOLDEN=1 ./container_test --gtest_filter='Golden*'
#include "core/error.hpp"
#include "io/output_file.hpp"
#include "io/tet_codec.hpp"
#include "io/tet_container.hpp"
#include "io/tet_reader.hpp"
#include "io/tet_writer.hpp"
#include "pipeline/write/label_order.hpp"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <numeric>
#include <random>
#include <set>
#include <string>
#include <tuple>
#include <vector>

namespace fs = std::filesystem;
using namespace tetstream;
using namespace tetstream::io;

namespace {

using Tet = std::array<std::uint64_t, 4>;

// ---------------------------------------------------------------- synthetic meshes

struct Mesh {
  std::vector<double> xyz;         // sorted by (x, y, z): index = label
  std::vector<std::uint64_t> ids;  // original index of each label
  std::vector<Tet> tets;           // positively oriented
  std::array<double, 3> lo{}, hi{};
};

// (nx+1)(ny+1)(nz+1) lattice points with spacings (sx, sy, sz); every cube split into 6
// tets; ids a fixed permutation (label * mult + add) mod N (mult odd and coprime with N).
Mesh lattice(int nx, int ny, int nz, double sx, double sy, double sz, std::uint64_t mult, std::uint64_t add) {
  Mesh m;
  const int px = nx + 1, py = ny + 1, pz = nz + 1;
  auto grid_index = [&](int i, int j, int k) { return (std::uint64_t(i) * py + j) * pz + k; };
  // Sorted by (x, y, z) is exactly the (i, j, k) lexicographic order.
  const std::uint64_t n = std::uint64_t(px) * py * pz;
  for (int i = 0; i < px; ++i)
    for (int j = 0; j < py; ++j)
      for (int k = 0; k < pz; ++k) m.xyz.insert(m.xyz.end(), {i * sx, j * sy, k * sz});
  for (std::uint64_t l = 0; l < n; ++l) m.ids.push_back((l * mult + add) % n);
  m.lo = {0, 0, 0};
  m.hi = {nx * sx, ny * sy, nz * sz};
  const int perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (int i = 0; i < nx; ++i)
    for (int j = 0; j < ny; ++j)
      for (int k = 0; k < nz; ++k)
        for (const auto& p : perms) {
          int c[3] = {i, j, k};
          std::array<std::array<int, 3>, 4> v;
          v[0] = {c[0], c[1], c[2]};
          for (int s = 0; s < 3; ++s) {
            c[p[s]] += 1;
            v[s + 1] = {c[0], c[1], c[2]};
          }
          // det[v1-v0, v2-v0, v3-v0] in lattice units (the spacings are positive).
          long d[3][3];
          for (int r = 0; r < 3; ++r)
            for (int q = 0; q < 3; ++q) d[r][q] = v[r + 1][q] - v[0][q];
          const long det = d[0][0] * (d[1][1] * d[2][2] - d[1][2] * d[2][1]) -
                           d[0][1] * (d[1][0] * d[2][2] - d[1][2] * d[2][0]) +
                           d[0][2] * (d[1][0] * d[2][1] - d[1][1] * d[2][0]);
          if (det < 0) std::swap(v[2], v[3]);
          Tet t;
          for (int s = 0; s < 4; ++s) t[s] = grid_index(v[s][0], v[s][1], v[s][2]);
          m.tets.push_back(t);
        }
  return m;
}

// The canonical form of format.md §4.1, computed the slow, obvious way: among the 12
// even permutations, the one whose first two labels are the two smallest.
Tet canonical(const Tet& t) {
  static const int even[12][4] = {{0, 1, 2, 3}, {0, 2, 3, 1}, {0, 3, 1, 2}, {1, 0, 3, 2}, {1, 2, 0, 3}, {1, 3, 2, 0},
                                  {2, 0, 1, 3}, {2, 1, 3, 0}, {2, 3, 0, 1}, {3, 0, 2, 1}, {3, 1, 0, 2}, {3, 2, 1, 0}};
  for (const auto& e : even) {
    const Tet r = {t[e[0]], t[e[1]], t[e[2]], t[e[3]]};
    if (r[0] < r[1] && r[1] < r[2] && r[1] < r[3]) return r;
  }
  ADD_FAILURE() << "tet with repeated labels";
  return t;
}

// Sort key of the stored order: (m, a, lo, hi, parity).
std::array<std::uint64_t, 5> stored_key(const Tet& c) {
  return {c[0], c[1], std::min(c[2], c[3]), std::max(c[2], c[3]), std::uint64_t(c[2] > c[3])};
}

std::vector<Tet> canonical_sorted(std::vector<Tet> tets) {
  for (auto& t : tets) t = canonical(t);
  std::sort(tets.begin(), tets.end(), [](const Tet& a, const Tet& b) { return stored_key(a) < stored_key(b); });
  return tets;
}

template <class L>
std::vector<L> flatten(const std::vector<Tet>& tets) {
  std::vector<L> out;
  for (const auto& t : tets)
    for (auto v : t) out.push_back(static_cast<L>(v));
  return out;
}

template <class L>
std::vector<Tet> unflatten(const std::vector<L>& labels) {
  std::vector<Tet> out(labels.size() / 4);
  for (std::size_t i = 0; i < out.size(); ++i)
    out[i] = {labels[4 * i], labels[4 * i + 1], labels[4 * i + 2], labels[4 * i + 3]};
  return out;
}

// Shuffles the tets and gives each a random even rotation: the encoder must not care.
std::vector<Tet> scramble(std::vector<Tet> tets, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::shuffle(tets.begin(), tets.end(), rng);
  static const int even[12][4] = {{0, 1, 2, 3}, {0, 2, 3, 1}, {0, 3, 1, 2}, {1, 0, 3, 2}, {1, 2, 0, 3}, {1, 3, 2, 0},
                                  {2, 0, 1, 3}, {2, 1, 3, 0}, {2, 3, 0, 1}, {3, 0, 2, 1}, {3, 1, 0, 2}, {3, 2, 1, 0}};
  for (auto& t : tets) {
    const auto& e = even[rng() % 12];
    t = {t[e[0]], t[e[1]], t[e[2]], t[e[3]]};
  }
  return tets;
}

// Random tets: distinct labels in [0, range), a mix of near and far neighbours, plus a
// fan with a huge group (escaped positions, full context slots).
std::vector<Tet> random_tets(std::size_t n, std::uint64_t range, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<Tet> tets;
  while (tets.size() < n) {
    const std::uint64_t m = rng() % range;
    Tet t{m, 0, 0, 0};
    for (int s = 1; s < 4; ++s) {
      std::uint64_t span = (rng() % 4 == 0) ? range : 64;
      t[s] = (m + 1 + rng() % span) % range;
    }
    std::set<std::uint64_t> d(t.begin(), t.end());
    if (d.size() == 4) tets.push_back(t);
  }
  if (range > 2000) {
    for (std::uint64_t i = 1; i + 2 < 1000; ++i) tets.push_back({0, i, i + 1, i + 2});
  }
  return tets;
}

// ---------------------------------------------------------------- files

struct TempDir {
  fs::path dir;
  TempDir() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir = fs::temp_directory_path() /
          ("tetstream_container_" + std::string(info->name()) + "_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
  }
  ~TempDir() { fs::remove_all(dir); }
  std::string operator/(const std::string& name) const { return (dir / name).string(); }
};

std::vector<std::uint8_t> slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

void spit(const std::string& path, const std::vector<std::uint8_t>& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}

TetFileHeader header_for(const Mesh& m, CoordType coords = CoordType::kFloat64) {
  TetFileHeader h;
  h.point_count = m.ids.size();
  h.input_count = m.ids.size();
  h.coord_type = coords;
  h.bbox_min = m.lo;
  h.bbox_max = m.hi;
  h.tool = "tetstream-test";
  h.options = R"({"test":true})";
  return h;
}

void write_mesh(const std::string& path, const Mesh& m, const TetFileHeader& h, const TetWriterOptions& o,
                std::size_t batch_tets = 1000) {
  TetWriter w(path, h, o);
  const std::size_t chunk = 7;  // points in odd-sized chunks
  for (std::size_t i = 0; i < m.ids.size(); i += chunk) {
    const std::size_t k = std::min(chunk, m.ids.size() - i);
    w.add_points(m.xyz.data() + 3 * i, m.ids.data() + i, k);
  }
  const auto labels = flatten<std::uint32_t>(m.tets);
  for (std::size_t i = 0; i < m.tets.size(); i += batch_tets) {
    const std::size_t k = std::min(batch_tets, m.tets.size() - i);
    w.add_tets(std::span<const std::uint32_t>(labels).subspan(4 * i, 4 * k));
  }
  w.finish();
}

std::vector<Tet> read_all(const TetReader& r) {
  std::vector<Tet> all;
  std::vector<std::uint64_t> labels;
  for (std::uint64_t k = 0; k < r.frame_count(); ++k) {
    r.read_frame(k, labels);
    const auto tets = unflatten(labels);
    all.insert(all.end(), tets.begin(), tets.end());
  }
  return all;
}

// Runs f, expecting an InputError whose message contains every one of `parts`.
template <class F>
void expect_input_error(F f, std::vector<std::string> parts) {
  try {
    f();
    ADD_FAILURE() << "no error; expected one mentioning '" << parts.front() << "'";
  } catch (const InputError& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    for (const auto& p : parts) EXPECT_NE(std::string(e.what()).find(p), std::string::npos) << e.what();
  }
}

// ---------------------------------------------------------------- CRC32C

TEST(Crc32c, KnownVectorsAndIncremental) {
  const std::string s = "123456789";
  EXPECT_EQ(crc32c(s.data(), s.size()), 0xE3069283u);
  EXPECT_EQ(crc32c(nullptr, 0), 0u);
  std::vector<std::uint8_t> zeros(32, 0);
  EXPECT_EQ(crc32c(zeros.data(), zeros.size()), 0x8A9136AAu);  // RFC 3720 B.4
  std::vector<std::uint8_t> data(1000);
  std::iota(data.begin(), data.end(), 0);
  const std::uint32_t whole = crc32c(data.data(), data.size());
  EXPECT_EQ(crc32c(data.data() + 333, 667, crc32c(data.data(), 333)), whole);
}

// Two pieces' CRCs give the whole one's, for every split (empty pieces included), and
// chained over many pieces as the ranks of a job combine theirs.
TEST(Crc32c, CombineGivesTheWholeStringsCrc) {
  std::vector<std::uint8_t> data(2053);
  std::uint32_t x = 12345;
  for (std::uint8_t& b : data) b = std::uint8_t((x = x * 1103515245u + 12345u) >> 16);
  const std::uint32_t whole = crc32c(data.data(), data.size());
  for (std::size_t cut = 0; cut <= data.size(); cut += 1 + cut / 3) {
    const std::uint32_t a = crc32c(data.data(), cut), b = crc32c(data.data() + cut, data.size() - cut);
    EXPECT_EQ(crc32c_combine(a, b, data.size() - cut), whole) << "cut at " << cut;
  }
  std::uint32_t chained = crc32c(nullptr, 0);
  for (std::size_t at = 0, piece = 1; at < data.size(); at += piece, piece = piece * 2 + 1) {
    const std::size_t n = std::min(piece, data.size() - at);
    chained = crc32c_combine(chained, crc32c(data.data() + at, n), n);
  }
  EXPECT_EQ(chained, whole);
  // Long pieces (1 MiB of zeros, twice): the combine's powers of x past small counts.
  std::vector<std::uint8_t> zeros(std::size_t(1) << 20, 0);
  std::uint32_t z = crc32c(zeros.data(), zeros.size());
  EXPECT_EQ(crc32c_combine(z, z, zeros.size()), crc32c(zeros.data(), zeros.size(), z));
}

// ---------------------------------------------------------------- codec

TEST(FrameCodec, RoundTripIsTheCanonicalStoredOrder) {
  const Mesh m = lattice(5, 4, 6, 1.0, 1.0, 1.0, 1, 0);
  FrameEncoder enc;
  FrameDecoder dec;
  EncodedFrame f;
  const auto labels = flatten<std::uint32_t>(scramble(m.tets, 7));
  enc.encode(labels, f);
  EXPECT_EQ(f.tet_count, m.tets.size());
  EXPECT_EQ(f.crc, crc32c(f.payload.data(), f.payload.size()));
  std::vector<std::uint32_t> out;
  dec.decode(f.payload, out);
  EXPECT_EQ(unflatten(out), canonical_sorted(m.tets));
  std::vector<std::uint64_t> out64;
  dec.decode(f.payload, out64);
  EXPECT_EQ(unflatten(out64), canonical_sorted(m.tets));
  EXPECT_LT(double(f.payload.size()) / double(m.tets.size()), 4.0) << "bytes per tet";
}

TEST(FrameCodec, BytesDependOnlyOnTheSetOfTets) {
  const Mesh m = lattice(4, 4, 4, 1.0, 1.0, 1.0, 1, 0);
  FrameEncoder enc;
  EncodedFrame a, b, c;
  enc.encode(flatten<std::uint32_t>(m.tets), a);
  for (std::uint64_t seed : {1, 2, 3}) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    enc.encode(flatten<std::uint32_t>(scramble(m.tets, seed)), b);
    EXPECT_EQ(a.payload, b.payload);
  }
  enc.encode(flatten<std::uint64_t>(m.tets), c);  // the label type does not matter either
  EXPECT_EQ(a.payload, c.payload);
  // Re-encoding the decoded (stored) order reproduces the frame: the order is stable.
  FrameDecoder dec;
  std::vector<std::uint32_t> out;
  dec.decode(a.payload, out);
  enc.encode(out, b);
  EXPECT_EQ(a.payload, b.payload);
}

TEST(FrameCodec, RandomAndWideLabels) {
  FrameEncoder enc;
  FrameDecoder dec;
  EncodedFrame f;
  for (std::uint64_t seed = 1; seed <= 6; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    const std::uint64_t range = seed % 2 ? 1000 : 5'000'000;
    auto tets = random_tets(3000, range, seed);
    std::vector<std::uint64_t> out;
    enc.encode(flatten<std::uint64_t>(tets), f);
    dec.decode(f.payload, out);
    EXPECT_EQ(unflatten(out), canonical_sorted(tets));
    // The same tets shifted beyond 32 bits.
    const std::uint64_t shift = (std::uint64_t(1) << 40) + seed;
    for (auto& t : tets)
      for (auto& v : t) v += shift;
    enc.encode(flatten<std::uint64_t>(tets), f);
    EXPECT_EQ(f.base_label, canonical_sorted(tets).front()[0]);
    dec.decode(f.payload, out);
    EXPECT_EQ(unflatten(out), canonical_sorted(tets));
    std::vector<std::uint32_t> narrow;
    EXPECT_THROW(dec.decode(f.payload, narrow), FrameError);
  }
}

TEST(FrameCodec, SingleTetAndDuplicates) {
  FrameEncoder enc;
  FrameDecoder dec;
  EncodedFrame f;
  const std::vector<Tet> one = {{9, 4, 7, 5}};
  enc.encode(flatten<std::uint32_t>(one), f);
  std::vector<std::uint64_t> out;
  dec.decode(f.payload, out);
  EXPECT_EQ(unflatten(out), canonical_sorted(one));
  // A multiset is kept as is, both orientations of the same labels too.
  const std::vector<Tet> dup = {{1, 2, 3, 4}, {1, 2, 3, 4}, {1, 2, 4, 3}};
  enc.encode(flatten<std::uint32_t>(dup), f);
  dec.decode(f.payload, out);
  EXPECT_EQ(unflatten(out), canonical_sorted(dup));
}

TEST(FrameCodec, RejectsBadInput) {
  FrameEncoder enc;
  EncodedFrame f;
  const std::vector<std::uint32_t> repeated = {1, 2, 2, 3};
  EXPECT_THROW(enc.encode(repeated, f), std::invalid_argument);
  EXPECT_THROW(enc.encode(std::span<const std::uint32_t>(), f), std::invalid_argument);
  const std::vector<std::uint32_t> ragged = {1, 2, 3};
  EXPECT_THROW(enc.encode(ragged, f), std::invalid_argument);
}

// Damaged payloads (the CRC is bypassed here) must give FrameError, never a crash or
// out-of-bounds access (this test runs under ASan in CI).
TEST(FrameCodec, CorruptPayloadsAreRejectedSafely) {
  const Mesh m = lattice(3, 3, 3, 1.0, 1.0, 1.0, 1, 0);
  FrameEncoder enc(1);
  EncodedFrame f;
  enc.encode(flatten<std::uint32_t>(m.tets), f);
  FrameDecoder dec;
  std::vector<std::uint64_t> out;
  const std::uint64_t seed = 12345;
  std::mt19937_64 rng(seed);
  int rejected = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    auto p = f.payload;
    const int flips = 1 + int(rng() % 3);
    for (int k = 0; k < flips; ++k) p[rng() % p.size()] ^= std::uint8_t(1u << (rng() % 8));
    if (trial % 5 == 0) p.resize(rng() % p.size());
    try {
      dec.decode(p, out);
    } catch (const FrameError&) {
      ++rejected;
    }
  }
  EXPECT_GT(rejected, 2900) << "seed " << seed;  // zstd's checksums catch nearly all flips
}

TEST(FrameCodec, Boundaries) {
  EXPECT_EQ(frame_boundaries(0, 10), (std::vector<std::size_t>{0}));
  EXPECT_EQ(frame_boundaries(10, 10), (std::vector<std::size_t>{0, 10}));
  EXPECT_EQ(frame_boundaries(11, 10), (std::vector<std::size_t>{0, 6, 11}));
  EXPECT_EQ(frame_boundaries(25, 10), (std::vector<std::size_t>{0, 9, 17, 25}));
}

// ---------------------------------------------------------------- writer and reader

TEST(Container, WriteReadRoundTrip) {
  TempDir tmp;
  const Mesh m = lattice(6, 5, 4, 0.5, 0.25, 2.0, 37, 11);
  TetWriterOptions o;
  o.frame_tets = 100;
  const std::string path = tmp / "mesh.tets";
  write_mesh(path, m, header_for(m), o, 250);
  EXPECT_FALSE(fs::exists(path + ".partial"));

  TetReader r(path);
  EXPECT_EQ(r.point_count(), m.ids.size());
  EXPECT_EQ(r.tet_count(), m.tets.size());
  EXPECT_EQ(r.header().label_width, 32u);
  EXPECT_EQ(r.header().tool, "tetstream-test");
  EXPECT_EQ(r.header().options, R"({"test":true})");
  EXPECT_EQ(r.header().bbox_max[2], 8.0);
  // 720 tets in batches of 250, 250, 220; each split into 3 frames of at most 100.
  ASSERT_EQ(m.tets.size(), 720u);
  EXPECT_EQ(r.frame_count(), 9u);
  EXPECT_EQ(r.frames()[0].tet_count, 84u);
  EXPECT_EQ(r.frames()[8].tet_count, 73u);
  EXPECT_EQ(r.frames()[8].first_tet, 720u - 73u);
  EXPECT_LT(double(r.tet_bytes()) / double(r.tet_count()), 6.0);

  // Each batch's frames, in stored order, concatenated in batch order.
  std::vector<Tet> expect;
  for (std::size_t i = 0; i < m.tets.size(); i += 250) {
    const std::vector<Tet> batch(m.tets.begin() + i, m.tets.begin() + std::min(m.tets.size(), i + 250));
    const auto b = frame_boundaries(batch.size(), 100);
    for (std::size_t f = 0; f + 1 < b.size(); ++f) {
      const auto part = canonical_sorted({batch.begin() + b[f], batch.begin() + b[f + 1]});
      expect.insert(expect.end(), part.begin(), part.end());
    }
  }
  EXPECT_EQ(read_all(r), expect);

  std::vector<double> xyz(3 * m.ids.size());
  std::vector<std::uint64_t> ids(m.ids.size());
  r.read_points(0, m.ids.size(), xyz.data(), ids.data());
  EXPECT_EQ(xyz, m.xyz);
  EXPECT_EQ(ids, m.ids);
  r.read_points(5, 1, nullptr, ids.data());
  EXPECT_EQ(ids[0], m.ids[5]);
  EXPECT_NO_THROW(r.verify_points());

  // --original-ids: labels map through the stored permutation.
  std::vector<std::uint64_t> labels;
  r.read_frame(1, labels);
  auto mapped = labels;
  r.map_to_original(mapped);
  for (std::size_t i = 0; i < labels.size(); ++i) EXPECT_EQ(mapped[i], m.ids[labels[i]]);
}

TEST(Container, Float32And64BitWidths) {
  TempDir tmp;
  const Mesh m = lattice(3, 2, 2, 0.1, 0.3, 0.7, 5, 1);
  TetFileHeader h = header_for(m, CoordType::kFloat32);
  h.label_width = 64;
  h.id_width = 64;
  h.bbox_max = {0.3000001, 0.6000001, 1.4000001};  // float rounding stays inside
  const std::string path = tmp / "f32.tets";
  write_mesh(path, m, h, {});
  TetReader r(path);
  EXPECT_EQ(r.header().coord_type, CoordType::kFloat32);
  EXPECT_EQ(r.header().label_width, 64u);
  EXPECT_EQ(r.header().point_record_bytes(), 20u);
  std::vector<double> xyz(3 * m.ids.size());
  std::vector<std::uint64_t> ids(m.ids.size());
  r.read_points(0, m.ids.size(), xyz.data(), ids.data());
  for (std::size_t i = 0; i < xyz.size(); ++i) EXPECT_EQ(xyz[i], double(float(m.xyz[i])));
  EXPECT_EQ(ids, m.ids);
  EXPECT_EQ(read_all(r), canonical_sorted(m.tets));
}

TEST(Container, SameBytesForAnyThreadCount) {
  TempDir tmp;
  const Mesh m = lattice(8, 8, 8, 1.0, 1.0, 1.0, 1, 0);
  TetWriterOptions o;
  o.frame_tets = 300;
  o.threads = 1;
  write_mesh(tmp / "t1.tets", m, header_for(m), o, 5000);
  o.threads = 4;
  write_mesh(tmp / "t4.tets", m, header_for(m), o, 5000);
  EXPECT_EQ(slurp(tmp / "t1.tets"), slurp(tmp / "t4.tets"));
}

TEST(Container, UnfinishedWriterLeavesNothing) {
  TempDir tmp;
  const Mesh m = lattice(2, 2, 2, 1.0, 1.0, 1.0, 1, 0);
  const std::string path = tmp / "gone.tets";
  {
    TetWriter w(path, header_for(m));
    w.add_points(m.xyz.data(), m.ids.data(), m.ids.size());
    EXPECT_TRUE(fs::exists(path + ".partial"));
  }
  EXPECT_FALSE(fs::exists(path + ".partial"));
  EXPECT_FALSE(fs::exists(path));
}

TEST(Container, WriterRejectsMisuse) {
  TempDir tmp;
  const Mesh m = lattice(2, 2, 2, 1.0, 1.0, 1.0, 1, 0);
  TetWriter w(tmp / "x.tets", header_for(m));
  const auto labels = flatten<std::uint32_t>(m.tets);
  EXPECT_THROW(w.add_tets(labels), std::logic_error);  // tets before the points
  std::vector<double> outside = {0, 0, 99};
  EXPECT_THROW(w.add_points(outside.data(), nullptr, 1), std::invalid_argument);
  TetFileHeader bad = header_for(m);
  bad.point_count = 0;
  EXPECT_THROW(TetWriter(tmp / "y.tets", bad), std::invalid_argument);
  w.add_points(m.xyz.data(), m.ids.data(), m.ids.size());
  const std::vector<std::uint32_t> beyond = {0, 1, 2, 27};
  EXPECT_THROW(w.add_tets(beyond), std::invalid_argument);
}

// A mesh written whole (whole.tets, batches of 400 tets in frames of 200), for tests
// that write the same tets in pieces and compare the bytes.
struct WrittenWhole {
  Mesh m = lattice(6, 6, 6, 1.0, 1.0, 1.0, 7, 3);
  TetFileHeader h = header_for(m);
  TetWriterOptions o = [] {
    TetWriterOptions o;
    o.frame_tets = 200;
    o.sync = false;
    return o;
  }();
  std::vector<std::uint32_t> labels = flatten<std::uint32_t>(m.tets);
  explicit WrittenWhole(const TempDir& tmp) { write_mesh(tmp / "whole.tets", m, h, o, 400); }
  // The tets [cut1, cut2) and [cut2, end) as fragment files a.tets and b.tets, in
  // batches of 400 (a batch's frames are cut as it alone would be).
  void write_fragments(const TempDir& tmp, std::size_t cut1, std::size_t cut2) const {
    const std::span<const std::uint32_t> all(labels);
    const std::size_t t = m.tets.size();
    ASSERT_GT(t, cut2);
    for (const auto& [first, last, name] : {std::tuple{cut1, cut2, "a.tets"}, std::tuple{cut2, t, "b.tets"}}) {
      auto f = TetWriter::fragment(tmp / name, h, o);
      for (std::size_t i = first; i < last; i += 400)
        f->add_tets(all.subspan(4 * i, 4 * std::min<std::size_t>(400, last - i)));
      f->finish();
      EXPECT_FALSE(fs::exists(tmp / (std::string(name) + ".partial")));
    }
  }
};

TEST(Container, ResumeGivesTheSameBytes) {
  TempDir tmp;
  const WrittenWhole whole(tmp);
  const Mesh& m = whole.m;
  const TetFileHeader& h = whole.h;
  const TetWriterOptions& o = whole.o;
  const std::span<const std::uint32_t> all(whole.labels);
  const std::string path = tmp / "resumed.tets";
  std::uint64_t committed = 0;
  std::vector<std::uint8_t> crashed;
  {
    TetWriter w(path, h, o);
    w.add_points(m.xyz.data(), m.ids.data(), m.ids.size());
    w.add_tets(all.subspan(0, 4 * 400));
    w.add_tets(all.subspan(4 * 400, 4 * 400));
    committed = w.checkpoint();
    w.add_tets(all.subspan(4 * 800, 4 * 400));  // lost in the "crash" (or kept, then cut)
    w.checkpoint();
    crashed = slurp(path + ".partial");  // what a killed process leaves behind
  }
  spit(path + ".partial", crashed);
  auto w = TetWriter::resume(path, h, committed, o);
  EXPECT_EQ(w->tets_written(), 800u);
  for (std::size_t i = 800; i < m.tets.size(); i += 400) {
    w->add_tets(all.subspan(4 * i, 4 * std::min<std::size_t>(400, m.tets.size() - i)));
  }
  w->finish();
  EXPECT_EQ(slurp(path), slurp(tmp / "whole.tets"));

  // A checkpoint inside a frame, or a header of another job, is refused.
  spit(path + ".partial", crashed);
  expect_input_error([&] { TetWriter::resume(path, h, committed - 3, o); }, {"frame"});
  spit(path + ".partial", crashed);
  auto other = h;
  other.options = "{}";
  expect_input_error([&] { TetWriter::resume(path, other, committed, o); }, {"header differs"});
}

// A container written in pieces (the ranks of a job under MPI): the first part by the
// container's writer, the others as fragment files that each rank copies into place
// (io::place_fragment), side by side, the writer then indexing them: the bytes of one
// writer. A damaged fragment, a fragment through a link, a replaced or linked
// container are refused.
TEST(Container, PlacedFragmentsGiveTheSameBytes) {
  TempDir tmp;
  const WrittenWhole whole(tmp);
  whole.write_fragments(tmp, 400, 1200);
  const auto& [m, h, o, labels] = whole;
  const std::string out = tmp / "placed.tets", partial = out + ".partial";
  auto identity = [](const std::string& path) {
    struct stat st {};
    EXPECT_EQ(::lstat(path.c_str(), &st), 0);
    return std::pair<std::uint64_t, std::uint64_t>{std::uint64_t(st.st_dev), std::uint64_t(st.st_ino)};
  };
  {
    TetWriter w(out, h, o);
    w.add_points(m.xyz.data(), m.ids.data(), m.ids.size());
    w.add_tets(std::span<const std::uint32_t>(labels).subspan(0, 4 * 400));
    const std::uint64_t at = w.checkpoint();
    const std::uint64_t a_bytes = fs::file_size(tmp / "a.tets"), b_bytes = fs::file_size(tmp / "b.tets");
    // The second piece first (the ranks place in any order), each at its offset.
    std::vector<FrameEntry> b = place_fragment(tmp / "b.tets", partial, at + a_bytes, h.point_count, identity(partial));
    std::vector<FrameEntry> frames = place_fragment(tmp / "a.tets", partial, at, h.point_count, identity(partial));
    ASSERT_FALSE(frames.empty());
    EXPECT_EQ(frames.front().offset, at);
    EXPECT_EQ(b.front().offset, at + a_bytes);
    frames.insert(frames.end(), b.begin(), b.end());
    w.adopt_placed_frames(frames, a_bytes + b_bytes);
    w.finish();
  }
  EXPECT_EQ(slurp(out), slurp(tmp / "whole.tets"));

  // Not into another file than the one being written (it was replaced), nor through a link.
  const std::string other = tmp / "other.tets.partial";
  spit(other, std::vector<std::uint8_t>(16, 0));
  EXPECT_THROW(place_fragment(tmp / "a.tets", other, 0, h.point_count, identity(out)), IoError);
  fs::create_symlink(other, tmp / "linked.tets.partial");
  EXPECT_THROW(place_fragment(tmp / "a.tets", tmp / "linked.tets.partial", 0, h.point_count, identity(other)), IoError);
  EXPECT_EQ(fs::file_size(other), 16u);
  // A flipped byte in a frame of the fragment: its file, offset and frame are named.
  std::vector<std::uint8_t> damaged = slurp(tmp / "b.tets");
  damaged[damaged.size() / 2] ^= 0x40;
  spit(tmp / "bad.tets", damaged);
  expect_input_error([&] { place_fragment(tmp / "bad.tets", other, 0, h.point_count, identity(other)); },
                     {"bad.tets", "byte", "checksum"});
  // A fragment through a link is not followed.
  fs::create_symlink(tmp / "b.tets", tmp / "link.tets");
  EXPECT_THROW(place_fragment(tmp / "link.tets", other, 0, h.point_count, identity(other)), IoError);
  // Frames the file does not hold are not adopted.
  {
    TetWriter w(tmp / "short.tets", h, o);
    w.add_points(m.xyz.data(), m.ids.data(), m.ids.size());
    const std::uint64_t at = w.checkpoint();
    const std::vector<FrameEntry> frames = {{at, 0, 10, 100, 0, 5}};
    EXPECT_THROW(w.adopt_placed_frames(frames, 100 + 16 + 4), IoError);
  }
  EXPECT_FALSE(fs::exists(tmp / "short.tets"));
}

// ---------------------------------------------------------------- damaged files

class Damaged : public ::testing::Test {
 protected:
  void SetUp() override {
    mesh = lattice(4, 4, 4, 1.0, 1.0, 1.0, 3, 2);
    TetWriterOptions o;
    o.frame_tets = 100;
    path = tmp / "good.tets";
    write_mesh(path, mesh, header_for(mesh), o);
    good = slurp(path);
    TetReader r(path);
    frames = r.frames();
    bad = tmp / "bad.tets";
  }
  TempDir tmp;
  Mesh mesh;
  std::string path, bad;
  std::vector<std::uint8_t> good;
  std::vector<FrameEntry> frames;
};

TEST_F(Damaged, TruncatedAnywhere) {
  for (std::size_t cut :
       {std::size_t(0), std::size_t(10), std::size_t(100), good.size() / 2, good.size() - 49, good.size() - 1}) {
    SCOPED_TRACE("cut at " + std::to_string(cut));
    spit(bad, {good.begin(), good.begin() + cut});
    expect_input_error([&] { TetReader r(bad); }, {bad + ": byte "});
  }
  spit(bad, {good.begin(), good.begin() + good.size() / 2});
  expect_input_error([&] { TetReader r(bad); }, {"truncated"});
}

TEST_F(Damaged, BitFlipInAFrameNamesTheFrameAndOffset) {
  auto b = good;
  const std::uint64_t at = frames[2].offset + kSectionHeaderSize + 60;
  b[at] ^= 0x10;
  spit(bad, b);
  TetReader r(bad);  // the index and footer are intact
  std::vector<std::uint64_t> labels;
  EXPECT_NO_THROW(r.read_frame(1, labels));
  expect_input_error([&] { r.read_frame(2, labels); },
                     {"byte " + std::to_string(frames[2].offset), "frame 2", "checksum mismatch"});
}

TEST_F(Damaged, CorruptFrameWithValidCrcNamesTheStream) {
  // Damage behind the CRC's back (as a buggy writer would): the codec's checks report it.
  auto b = good;
  const std::uint64_t payload = frames[1].offset + kSectionHeaderSize;
  const std::uint64_t len = frames[1].length;
  b[payload + 49] ^= 0x01;  // inside stream 0's zstd frame header
  put_u32(b.data() + payload + len, crc32c(b.data() + payload, len));
  spit(bad, b);
  TetReader r(bad);
  std::vector<std::uint64_t> labels;
  expect_input_error([&] { r.read_frame(1, labels); },
                     {"frame 1", "stream HEAD", "byte " + std::to_string(payload + 48)});
}

TEST_F(Damaged, WrongVersionAndMagic) {
  auto b = good;
  b[8] = 3;  // version 3.0 (1 and 2 are read)
  spit(bad, b);
  expect_input_error([&] { TetReader r(bad); }, {"byte 8", "unsupported container version 3.0"});
  b = good;
  b[0] = 'P';
  spit(bad, b);
  expect_input_error([&] { TetReader r(bad); }, {"byte 0", "not a .tets container"});
  spit(bad, {'h', 'e', 'l', 'l', 'o'});
  expect_input_error([&] { TetReader r(bad); }, {"not a .tets container"});
}

TEST_F(Damaged, HeaderIndexFooterAndPoints) {
  auto b = good;
  b[kPreambleSize + kSectionHeaderSize + 30] ^= 0x04;  // inside HEAD (bbox)
  spit(bad, b);
  expect_input_error([&] { TetReader r(bad); }, {"header: checksum mismatch"});
  b = good;
  b[b.size() - 20] ^= 0x01;  // footer totals
  spit(bad, b);
  expect_input_error([&] { TetReader r(bad); }, {"footer checksum mismatch"});
  b = good;
  b[b.size() - kFooterSize - 10] ^= 0x01;  // inside the frame index
  spit(bad, b);
  expect_input_error([&] { TetReader r(bad); }, {"index: checksum mismatch"});
  b = good;
  b[kPreambleSize + 200] ^= 0x01;  // a point
  spit(bad, b);
  TetReader r(bad);
  expect_input_error([&] { r.verify_points(); }, {"points: checksum mismatch"});
}

TEST_F(Damaged, UnknownSectionsAreSkippedUnlessCritical) {
  // Splice an optional section before INDX and list it in the directory; then mark it critical.
  for (const bool critical : {false, true}) {
    SCOPED_TRACE(critical ? "critical" : "optional");
    TetReader r(path);
    std::vector<std::uint8_t> b(good.begin(), good.begin() + (good.size() - kFooterSize));
    Footer foot;
    ASSERT_TRUE(
        parse_footer(std::span<const std::uint8_t, kFooterSize>(good.data() + good.size() - kFooterSize, kFooterSize),
                     foot)
            .empty());
    b.resize(foot.index_offset);
    const std::uint64_t extra_at = b.size();
    const std::vector<std::uint8_t> payload = {'h', 'u', 'l', 'l'};
    const auto sh = section_header(make_tag("hull"), critical ? kSectionCritical : 0, payload.size());
    b.insert(b.end(), sh.begin(), sh.end());
    b.insert(b.end(), payload.begin(), payload.end());
    append_u32(b, crc32c(payload.data(), payload.size()));
    auto sections = r.sections();
    sections.push_back({make_tag("hull"), critical ? kSectionCritical : 0, extra_at, payload.size()});
    foot.index_offset = b.size();
    const auto index = serialize_index(sections, r.frames());
    const auto ih = section_header(kTagIndex, kSectionCritical, index.size());
    b.insert(b.end(), ih.begin(), ih.end());
    b.insert(b.end(), index.begin(), index.end());
    append_u32(b, crc32c(index.data(), index.size()));
    const auto ft = serialize_footer(foot);
    b.insert(b.end(), ft.begin(), ft.end());
    spit(bad, b);
    if (critical) {
      expect_input_error([&] { TetReader x(bad); }, {"unknown critical section hull"});
    } else {
      TetReader x(bad);
      EXPECT_EQ(read_all(x).size(), mesh.tets.size());
    }
  }
}

// ---------------------------------------------------------------- golden files

struct Golden {
  const char* name;
  Mesh mesh;
  TetFileHeader header;
  TetWriterOptions options;
};

// A mesh whose points are in the sort's order along `axis`, relabelled in version 2's
// order (one brick: fewer than 2^10 points), its tets in the stored order.
Mesh relabelled(const Mesh& sorted, int axis) {
  std::vector<std::uint32_t> new_of_old;
  pipeline::brick_permutation(sorted.xyz.data(), sorted.ids.size(), axis, new_of_old);
  Mesh m = sorted;
  for (std::size_t i = 0; i < new_of_old.size(); ++i) {
    for (int k = 0; k < 3; ++k) m.xyz[3 * new_of_old[i] + std::size_t(k)] = sorted.xyz[3 * i + std::size_t(k)];
    m.ids[new_of_old[i]] = sorted.ids[i];
  }
  for (Tet& t : m.tets)
    for (auto& v : t) v = new_of_old[v];
  m.tets = canonical_sorted(m.tets);
  return m;
}

// The recipes of the golden files; docs/format.md points here.
std::vector<Golden> goldens() {
  std::vector<Golden> g;
  {
    // 4x4x4 points (3^3 cubes, 162 tets), float64, 32-bit labels and ids, 3 frames.
    Mesh m = lattice(3, 3, 3, 0.5, 0.25, 1.0, 37, 11);
    TetFileHeader h = header_for(m);
    h.input_count = 70;  // as if 6 duplicates had been merged
    h.tool = "tetstream golden";
    h.options = R"({"recipe":"lattice 3x3x3, 6 tets per cube, ids 37*label+11 mod 64","frame_tets":60})";
    TetWriterOptions o;
    o.frame_tets = 60;
    g.push_back({"golden_v1_f64_u32.golden", std::move(m), h, o});
  }
  {
    // 3x2x4 points (2x1x3 cubes, 36 tets), float32, 64-bit labels and ids, 1 frame.
    Mesh m = lattice(2, 1, 3, 0.125, 2.0, 0.5, 5, 3);
    TetFileHeader h = header_for(m, CoordType::kFloat32);
    h.label_width = 64;
    h.id_width = 64;
    h.tool = "tetstream golden";
    h.options = R"({"recipe":"lattice 2x1x3, float32, 64-bit labels"})";
    g.push_back({"golden_v1_f32_u64.golden", std::move(m), h, {}});
  }
  {
    // Version 2 (format.md §3.4): 5x4x4 points (4x3x3 cubes, 216 tets), float64, x the
    // longest axis, so the lattice's order is the sort's; one brick, relabelled by
    // brick_permutation, the tets in the stored order of their new labels; 4 frames.
    Mesh m = relabelled(lattice(4, 3, 3, 1.0, 0.5, 0.25, 23, 5), 0);
    TetFileHeader h = header_for(m);
    h.version_major = kVersionMajorBricks;
    h.tool = "tetstream golden";
    h.options = R"({"recipe":"lattice 4x3x3, ids 23*label+5 mod 80, brick labels","frame_tets":60})";
    TetWriterOptions o;
    o.frame_tets = 60;
    g.push_back({"golden_v2_f64_u32.golden", std::move(m), h, o});
  }
  return g;
}

TEST(Golden, WriterReproducesTheGoldenFilesByteForByte) {
  TempDir tmp;
  const bool update = std::getenv("TETSTREAM_UPDATE_GOLDEN") != nullptr;
  for (const auto& g : goldens()) {
    SCOPED_TRACE(g.name);
    const std::string fresh = tmp / g.name;
    TetWriterOptions o = g.options;
    o.sync = false;
    write_mesh(fresh, g.mesh, g.header, o, 10000);
    const std::string golden = std::string(TETSTREAM_TEST_DATA_DIR) + "/" + g.name;
    if (update) fs::copy_file(fresh, golden, fs::copy_options::overwrite_existing);
    ASSERT_TRUE(fs::exists(golden)) << "missing " << golden;
    EXPECT_EQ(slurp(fresh), slurp(golden))
        << "the writer no longer reproduces " << golden
        << ": a format change (bump the version), or a zstd release that compresses differently "
           "(then the reader test below still passes; regenerate with TETSTREAM_UPDATE_GOLDEN=1)";
  }
}

TEST(Golden, ReaderReadsTheGoldenFiles) {
  for (const auto& g : goldens()) {
    SCOPED_TRACE(g.name);
    TetReader r(std::string(TETSTREAM_TEST_DATA_DIR) + "/" + g.name);
    EXPECT_EQ(r.version_major(), g.header.version_major);
    EXPECT_EQ(r.version_minor(), 0);
    EXPECT_EQ(r.header().tool, g.header.tool);
    EXPECT_EQ(r.header().options, g.header.options);
    EXPECT_EQ(r.header().point_count, g.mesh.ids.size());
    EXPECT_EQ(r.header().input_count, g.header.input_count);
    EXPECT_EQ(r.header().coord_type, g.header.coord_type);
    EXPECT_EQ(r.header().bbox_max, g.header.bbox_max);
    std::vector<Tet> expect;
    const auto b = frame_boundaries(g.mesh.tets.size(), g.options.frame_tets);
    for (std::size_t f = 0; f + 1 < b.size(); ++f) {
      const auto part = canonical_sorted({g.mesh.tets.begin() + b[f], g.mesh.tets.begin() + b[f + 1]});
      expect.insert(expect.end(), part.begin(), part.end());
    }
    EXPECT_EQ(r.frame_count(), b.size() - 1);
    EXPECT_EQ(read_all(r), expect);
    std::vector<double> xyz(3 * r.point_count());
    std::vector<std::uint64_t> ids(r.point_count());
    r.read_points(0, r.point_count(), xyz.data(), ids.data());
    EXPECT_EQ(ids, g.mesh.ids);
    for (std::size_t i = 0; i < xyz.size(); ++i) {
      EXPECT_EQ(xyz[i], g.header.coord_type == CoordType::kFloat32 ? double(float(g.mesh.xyz[i])) : g.mesh.xyz[i]);
    }
    EXPECT_NO_THROW(r.verify_points());
  }
}

}  // namespace
