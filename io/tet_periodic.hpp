#pragma once
// The two sections of a periodic container (docs/format.md §6, docs/periodic.md):
//
//   PBOX  the box: the period along x, y, z (the points lie in [0, L) on each axis) and
//         the axis whose lexicographic order (axis, axis+1, axis+2) broke the ties of
//         the symbolic perturbation (verify repeats it);
//   POFS  each tet's vertex offsets, one zstd frame a TETF frame, in the tets' stored
//         order: a u16 per tet, 729 ca + 27 cb + cc for the vertices a, b, c of the
//         stored (m, a, b, c), each c = 9 (ox+1) + 3 (oy+1) + (oz+1) the vertex's offset
//         in periods relative to m (each in -1, 0, 1): vertex a stands at
//         x(a) + (ox, oy, oz) * L when m stands at x(m).
//
// Both are critical: a reader that does not know them refuses the file.
#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace tetstream::io {

class TetReader;

struct PeriodicBox {
  std::array<double, 3> period{1, 1, 1};
  int sort_axis = 0;
};
inline constexpr std::size_t kPeriodicBoxBytes = 32;

std::vector<std::uint8_t> serialize_periodic_box(const PeriodicBox& box);
// Throws InputError naming `file` and the section when the payload is malformed.
PeriodicBox parse_periodic_box(std::span<const std::uint8_t> payload, const std::string& file);

// One vertex offset in {-1, 0, 1}^3 as 0..26, and a tet's three as one u16.
inline int offset_code(const int o[3]) { return 9 * (o[0] + 1) + 3 * (o[1] + 1) + (o[2] + 1); }
inline void offset_of_code(int c, int o[3]) {
  o[0] = c / 9 - 1;
  o[1] = c / 3 % 3 - 1;
  o[2] = c % 3 - 1;
}
inline constexpr int kZeroOffsetCode = 13;
inline std::uint16_t tet_offset_code(int ca, int cb, int cc) { return std::uint16_t(729 * ca + 27 * cb + cc); }
inline void tet_offset_codes(std::uint16_t code, int c[3]) {
  c[0] = code / 729;
  c[1] = code / 27 % 27;
  c[2] = code % 27;
}

// Builds POFS: add each frame's codes in frame order, then payload().
class PeriodicOffsetsWriter {
 public:
  // Returns the frame's compressed bytes (valid until the next add): a resumable job
  // keeps them, and add_compressed() gives them back to a resumed writer.
  std::span<const std::uint8_t> add_frame(std::span<const std::uint16_t> codes);
  void add_compressed(std::span<const std::uint8_t> bytes, std::uint32_t tets);
  std::vector<std::uint8_t> payload() const;

 private:
  struct Entry {
    std::uint64_t offset;
    std::uint32_t bytes, tets;
  };
  std::vector<Entry> entries_;
  std::vector<std::uint8_t> data_;
};

// Reads frame k's codes (frame k's tet count of them) from a container opened with
// TetReader::Periodic::kAccept; InputError naming the file when POFS is missing,
// malformed or disagrees with the frame index.
class PeriodicOffsetsReader {
 public:
  explicit PeriodicOffsetsReader(const TetReader& reader);
  void read(std::uint64_t k, std::vector<std::uint16_t>& codes) const;

 private:
  const TetReader& reader_;
  std::span<const std::uint8_t> payload_;
};

}  // namespace tetstream::io
