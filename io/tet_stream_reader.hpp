#pragma once
// Reads a .tets container front to back from a stream that cannot seek (a pipe:
// `tetstream run big.f64 -o - | tetstream cat -`), so the reader runs while the writer
// still writes. The container's order allows it (docs/format.md): preamble, HEAD,
// PNTS, the frames, INDX, footer; the writer only appends.
//
//   io::TetStreamReader r(STDIN_FILENO, "-");   // preamble, HEAD, PNTS (CRC checked)
//   std::vector<std::uint64_t> tets;
//   while (r.next_frame(tets)) { ... }           // each frame's CRC and codec checked
//   // false after INDX and the footer were read and agree with what was streamed
//
// Every check the random-access TetReader makes is made here too, in stream order: a
// frame is handed out only after its own CRC and decoding passed; the index and the
// footer, read last, must agree with the frames seen (so a truncated or spliced stream
// fails at its end with an InputError "NAME: byte OFFSET: PROBLEM", and a consumer must
// treat its output as complete only when next_frame() returned false).
//
// Memory: the original indices of the points when asked for (8 bytes a point, for
// map_to_original), else one chunk of points at a time; one frame's payload.
#include "io/tet_codec.hpp"
#include "io/tet_container.hpp"

#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace tetstream::io {

class TetStreamReader {
 public:
  // Reads up to the end of PNTS from `fd` (not closed). keep_ids: keep the points'
  // original indices for map_to_original(). Throws InputError, IoError.
  TetStreamReader(int fd, std::string name, bool keep_ids = false);

  const TetFileHeader& header() const { return header_; }
  std::uint64_t point_count() const { return header_.point_count; }

  // The next frame's labels (4 per tet, stored order); false at the end of the stream
  // once the index and footer check out.
  bool next_frame(std::vector<std::uint64_t>& labels);
  // Labels to original indices (keep_ids must have been set).
  void map_to_original(std::span<std::uint64_t> labels) const;

  std::uint64_t tets_read() const { return tets_; }
  std::uint64_t frames_read() const { return frames_.size(); }

 private:
  [[noreturn]] void fail(std::uint64_t offset, const std::string& problem) const;
  // Exactly n bytes, or an InputError "truncated" at the current offset.
  void read_exactly(void* data, std::size_t n, const char* what);
  // A section's header (tag, flags, length); the payload and its CRC follow.
  std::uint64_t read_section_header(std::uint32_t& tag);
  void read_payload(std::vector<std::uint8_t>& payload, std::uint64_t length, const std::string& what);

  int fd_;
  std::string name_;
  std::uint64_t offset_ = 0;  // bytes read so far
  TetFileHeader header_;
  std::vector<std::uint64_t> ids_;
  std::vector<SectionEntry> sections_;  // as streamed: HEAD, PNTS
  std::vector<FrameEntry> frames_;      // as streamed
  std::vector<std::uint8_t> payload_;
  FrameDecoder decoder_;
  std::uint64_t tets_ = 0;
  bool done_ = false;
};

}  // namespace tetstream::io
