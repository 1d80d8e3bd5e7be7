#pragma once
// The frame codec of the .tets container (docs/format.md §3.5 and §4): a pure function
// from a batch of tetrahedra to the bytes of one TETF payload, and back.
//
//   FrameEncoder enc;                 // one per thread: it owns scratch and a zstd context
//   EncodedFrame f;
//   enc.encode(labels, f);            // labels: 4 per tet, positively oriented
//   ... hand f to TetWriter::add_frame() in sequence order ...
//
//   FrameDecoder dec;                 // one per thread
//   dec.decode(f.payload, labels);    // the same tets, in stored (canonical) order
//
// Determinism: the bytes depend only on the set of tetrahedra (and the zstd level and
// library version), not on their order in the batch, on the even rotation each was given
// in, or on the thread that encodes them. So a pipeline can encode frames on any number
// of threads and get the same file. The encoder sorts the tets (by smallest label, ...)
// and rotates each by an even permutation (orientation is kept); decoding returns that
// stored order (format.md §4.1).
//
// Cost: about 1.5 bytes per tet on slab-ordered uniform points (16 raw); see
// scripts/bench-format for throughput.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace tetstream::io {

inline constexpr std::uint32_t kMaxFrameTets = 1u << 24;      // format.md §3.5
inline constexpr std::uint32_t kDefaultFrameTets = 1u << 20;  // the writer's frame size
inline constexpr int kDefaultZstdLevel = 1;                   // the streams are already small; see bench-format
inline constexpr std::size_t kFrameHeaderSize = 48;
inline constexpr std::uint8_t kCodecLowerStar = 1;
inline constexpr int kFrameStreams = 6;

// An encoded TETF payload and the facts the frame index records about it.
struct EncodedFrame {
  std::vector<std::uint8_t> payload;
  std::uint32_t tet_count = 0;
  std::uint64_t base_label = 0, max_label = 0;
  std::uint32_t crc = 0;  // CRC32C of payload (the section trailer)
};

// The 48-byte header at the start of a TETF payload.
struct FrameHeader {
  std::uint32_t tet_count = 0;
  std::uint8_t codec = 0, ctx_log2 = 0;
  std::uint64_t base_label = 0, max_label = 0;
  std::uint32_t stream_size[kFrameStreams] = {};
};
// Returns an empty string when the header is well formed, else the problem.
std::string parse_frame_header(std::span<const std::uint8_t> payload, FrameHeader& h);

// A malformed payload: what is wrong, and the byte offset within the payload where the
// offending part (header field or stream) starts.
class FrameError : public std::runtime_error {
 public:
  FrameError(const std::string& what, std::uint64_t offset) : std::runtime_error(what), offset_(offset) {}
  std::uint64_t offset() const noexcept { return offset_; }

 private:
  std::uint64_t offset_;
};

class FrameEncoder {
 public:
  explicit FrameEncoder(int zstd_level = kDefaultZstdLevel);
  ~FrameEncoder();
  FrameEncoder(const FrameEncoder&) = delete;
  FrameEncoder& operator=(const FrameEncoder&) = delete;

  // labels.size() = 4 * T with 1 <= T <= kMaxFrameTets; the four labels of each tet
  // distinct. Throws std::invalid_argument otherwise. `out` is overwritten (its
  // payload's capacity is reused).
  void encode(std::span<const std::uint32_t> labels, EncodedFrame& out);
  void encode(std::span<const std::uint64_t> labels, EncodedFrame& out);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

class FrameDecoder {
 public:
  FrameDecoder();
  ~FrameDecoder();
  FrameDecoder(const FrameDecoder&) = delete;
  FrameDecoder& operator=(const FrameDecoder&) = delete;

  // Decodes one TETF payload into `labels` (resized to 4 * T), tets in stored order,
  // each as (m, a, b, c) of format.md §4.1. Throws FrameError for anything malformed;
  // the 32-bit form also when a label does not fit.
  void decode(std::span<const std::uint8_t> payload, std::vector<std::uint64_t>& labels);
  void decode(std::span<const std::uint8_t> payload, std::vector<std::uint32_t>& labels);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Splits `n` tets into the fewest frames of at most `max_tets`, of sizes as equal as
// possible. Returns the boundaries {0, b1, ..., n} (just {0} for n = 0).
std::vector<std::size_t> frame_boundaries(std::size_t n, std::size_t max_tets);

}  // namespace tetstream::io
