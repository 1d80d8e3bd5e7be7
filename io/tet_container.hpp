#pragma once
// The `.tets` container: constants, on-disk records and their (de)serialisation,
// shared by the writer (io/tet_writer.hpp), the reader (io/tet_reader.hpp) and the
// frame codec (io/tet_codec.hpp). docs/format.md is the normative description; every
// constant and record here names the section of it that defines it.
//
//   Preamble | HEAD | PNTS | TETF* | INDX | Footer        (format.md §3)
//
// All multi-byte integers on disk are little-endian; the helpers below read and write
// them byte by byte, so the code is correct on any host.
#include <array>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <vector>

namespace tetstream::io {

// ---- §3.1 preamble, §3.7 footer ----
inline constexpr std::array<std::uint8_t, 8> kFileMagic = {0x89, 'T', 'E', 'T', 'S', '\r', '\n', 0x1A};
inline constexpr std::array<std::uint8_t, 8> kFooterMagic = {'T', 'E', 'T', 'S', 'E', 'N', 'D', 0x1A};
// Major versions: 1, labels in the sort's order along one axis; 2, the same layout with
// the labels in bricks along a space-filling curve (format.md §1, §3.4). A reader reads
// both; `run` writes 2, the periodic and the other writers 1.
inline constexpr std::uint16_t kVersionMajor = 1;
inline constexpr std::uint16_t kVersionMajorBricks = 2;
inline constexpr std::uint16_t kVersionMinor = 0;
inline bool version_readable(std::uint16_t major) { return major == kVersionMajor || major == kVersionMajorBricks; }
// §3.4: the labels a brick of version 2 holds, 2 N^(2/3) rounded up to a power of two (at
// least 2^10, at most 2^31; the last brick may be shorter). A power of two, so either it
// divides a frame block (frame_block_labels, a power of two) or a block divides it:
// ranges aligned to the larger of the two are aligned to both.
std::uint64_t brick_labels(std::uint64_t point_count);
inline constexpr std::size_t kPreambleSize = 16;
inline constexpr std::size_t kFooterSize = 48;

// ---- §3.2 sections ----
inline constexpr std::size_t kSectionHeaderSize = 16;  // tag, flags, length
inline constexpr std::size_t kSectionTrailerSize = 4;  // CRC32C of the payload
inline constexpr std::uint32_t kSectionCritical = 1;

constexpr std::uint32_t make_tag(const char (&s)[5]) {
  return std::uint32_t(std::uint8_t(s[0])) | std::uint32_t(std::uint8_t(s[1])) << 8 |
         std::uint32_t(std::uint8_t(s[2])) << 16 | std::uint32_t(std::uint8_t(s[3])) << 24;
}
inline constexpr std::uint32_t kTagHead = make_tag("HEAD");
inline constexpr std::uint32_t kTagPoints = make_tag("PNTS");
inline constexpr std::uint32_t kTagFrame = make_tag("TETF");
inline constexpr std::uint32_t kTagIndex = make_tag("INDX");
// A periodic triangulation (docs/periodic.md, format.md §6): the box, and each tet's
// vertex offsets. Both critical, so a reader that does not know them refuses the file.
inline constexpr std::uint32_t kTagPeriodicBox = make_tag("PBOX");
inline constexpr std::uint32_t kTagPeriodicOffsets = make_tag("POFS");
std::string tag_name(std::uint32_t tag);  // "HEAD", or "0x..." when not printable

// ---- §3.3 header ----
enum class CoordType : std::uint8_t { kFloat32 = 1, kFloat64 = 2 };
inline std::size_t coord_bytes(CoordType t) { return t == CoordType::kFloat32 ? 4 : 8; }

// What the writer is told up front and the reader returns (HEAD's fields).
struct TetFileHeader {
  std::uint64_t point_count = 0;
  std::uint64_t input_count = 0;  // before duplicate merging; 0: unknown
  CoordType coord_type = CoordType::kFloat64;
  unsigned label_width = 0;  // 32 or 64; 0: the writer picks (32 when point_count <= 2^32)
  unsigned id_width = 0;     // 32 or 64; 0: the writer picks from max(input_count, point_count)
  std::array<double, 3> bbox_min{0, 0, 0}, bbox_max{0, 0, 0};
  std::string tool;     // e.g. "tetstream 0.1.0"
  std::string options;  // how the file was made, normally a JSON object
  // The preamble's major version (not a HEAD field): kVersionMajor, or
  // kVersionMajorBricks for labels in format 2's order.
  std::uint16_t version_major = kVersionMajor;

  std::size_t point_record_bytes() const { return 3 * coord_bytes(coord_type) + id_width / 8; }
  // Fills label_width and id_width when 0 and checks everything; throws
  // std::invalid_argument for a header no container can hold.
  void resolve_and_validate();
};

inline constexpr std::size_t kHeadFixedSize = 72;  // up to tool_length
std::vector<std::uint8_t> serialize_head(const TetFileHeader& h);
// Parses HEAD's payload; returns an empty string on success, else the problem.
std::string parse_head(std::span<const std::uint8_t> payload, TetFileHeader& h);

// ---- §3.6 index ----
struct SectionEntry {
  std::uint32_t tag = 0, flags = 0;
  std::uint64_t offset = 0, length = 0;  // offset of the tag; payload length
};
inline constexpr std::size_t kSectionEntrySize = 24;

struct FrameEntry {
  std::uint64_t offset = 0;     // of the TETF section's tag
  std::uint64_t first_tet = 0;  // ordinal of its first tet in the file
  std::uint32_t tet_count = 0;
  std::uint32_t length = 0;  // TETF payload length
  std::uint64_t base_label = 0, max_label = 0;
};
inline constexpr std::size_t kFrameEntrySize = 40;

struct Footer {
  std::uint64_t index_offset = 0, tet_count = 0, frame_count = 0, point_count = 0;
};

std::vector<std::uint8_t> serialize_index(std::span<const SectionEntry> sections, std::span<const FrameEntry> frames);
std::array<std::uint8_t, kFooterSize> serialize_footer(const Footer& f);
// Both return an empty string on success, else the problem.
std::string parse_footer(std::span<const std::uint8_t, kFooterSize> bytes, Footer& f);
std::string parse_index(std::span<const std::uint8_t> payload, std::vector<SectionEntry>& sections,
                        std::vector<FrameEntry>& frames);

// ---- §2 CRC32C (Castagnoli), hardware-accelerated where the CPU has SSE4.2 ----
std::uint32_t crc32c(const void* data, std::size_t n, std::uint32_t crc = 0);
// Incremental form: crc32c(ab) == crc32c(b, n_b, crc32c(a, n_a)).
// The CRC of a byte string from the CRCs of its two pieces, without their bytes:
// crc32c(ab) == crc32c_combine(crc32c(a), crc32c(b), n_b). How the ranks of a job that
// wrote one section side by side agree on its checksum (pipeline/point_sort_distributed).
std::uint32_t crc32c_combine(std::uint32_t crc_a, std::uint32_t crc_b, std::uint64_t n_b);

// ---- little-endian helpers ----
inline void put_u16(std::uint8_t* p, std::uint16_t v) { p[0] = std::uint8_t(v), p[1] = std::uint8_t(v >> 8); }
inline void put_u32(std::uint8_t* p, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = std::uint8_t(v >> (8 * i));
}
inline void put_u64(std::uint8_t* p, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) p[i] = std::uint8_t(v >> (8 * i));
}
inline std::uint16_t get_u16(const std::uint8_t* p) { return std::uint16_t(p[0] | p[1] << 8); }
inline std::uint32_t get_u32(const std::uint8_t* p) {
  std::uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = v << 8 | p[i];
  return v;
}
inline std::uint64_t get_u64(const std::uint8_t* p) {
  std::uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = v << 8 | p[i];
  return v;
}
inline void put_f64(std::uint8_t* p, double d) {
  std::uint64_t v;
  std::memcpy(&v, &d, 8);
  put_u64(p, v);
}
inline double get_f64(const std::uint8_t* p) {
  const std::uint64_t v = get_u64(p);
  double d;
  std::memcpy(&d, &v, 8);
  return d;
}
inline void append_u32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  const std::size_t at = out.size();
  out.resize(at + 4);
  put_u32(out.data() + at, v);
}
inline void append_u64(std::vector<std::uint8_t>& out, std::uint64_t v) {
  const std::size_t at = out.size();
  out.resize(at + 8);
  put_u64(out.data() + at, v);
}

// A section header, as bytes.
std::array<std::uint8_t, kSectionHeaderSize> section_header(std::uint32_t tag, std::uint32_t flags,
                                                            std::uint64_t length);

}  // namespace tetstream::io
