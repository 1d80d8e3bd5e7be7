#include "io/tet_stream_reader.hpp"

#include "core/error.hpp"

#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <unistd.h>

namespace tetstream::io {

void TetStreamReader::fail(std::uint64_t offset, const std::string& problem) const {
  throw InputError::at_byte(name_, offset, problem);
}

void TetStreamReader::read_exactly(void* data, std::size_t n, const char* what) {
  auto* p = static_cast<std::uint8_t*>(data);
  std::size_t got = 0;
  while (got < n) {
    const ssize_t r = ::read(fd_, p + got, n - got);
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) throw IoError(name_ + ": read failed: " + std::strerror(errno));
    if (r == 0) fail(offset_ + got, std::string("truncated in ") + what + " (the stream ended early)");
    got += std::size_t(r);
  }
  offset_ += n;
}

std::uint64_t TetStreamReader::read_section_header(std::uint32_t& tag) {
  std::uint8_t h[kSectionHeaderSize];
  read_exactly(h, sizeof h, "a section header");
  tag = get_u32(h);
  const std::uint32_t flags = get_u32(h + 4);
  if (tag != kTagHead && tag != kTagPoints && tag != kTagFrame && tag != kTagIndex && (flags & kSectionCritical))
    fail(offset_ - sizeof h, "unknown critical section " + tag_name(tag) + " (written by a newer version?)");
  return get_u64(h + 8);
}

void TetStreamReader::read_payload(std::vector<std::uint8_t>& payload, std::uint64_t length, const std::string& what) {
  // A frame is at most a few MiB; a length beyond any section this format writes is
  // damage, not an allocation to attempt.
  if (length > (std::uint64_t(1) << 40)) fail(offset_ - 8, what + ": implausible section length");
  const std::uint64_t at = offset_;
  payload.resize(std::size_t(length) + kSectionTrailerSize);
  read_exactly(payload.data(), payload.size(), what.c_str());
  if (crc32c(payload.data(), std::size_t(length)) != get_u32(payload.data() + length))
    fail(at - kSectionHeaderSize, what + ": checksum mismatch (the stream is damaged)");
  payload.resize(std::size_t(length));
}

TetStreamReader::TetStreamReader(int fd, std::string name, bool keep_ids) : fd_(fd), name_(std::move(name)) {
  std::uint8_t pre[kPreambleSize];
  read_exactly(pre, sizeof pre, "the preamble");
  if (std::memcmp(pre, kFileMagic.data(), kFileMagic.size()) != 0) fail(0, "not a .tets container (bad magic)");
  if (!version_readable(get_u16(pre + 8)))
    fail(8, "unsupported container version " + std::to_string(get_u16(pre + 8)) + " (this reader reads " +
                std::to_string(kVersionMajor) + ".x and " + std::to_string(kVersionMajorBricks) + ".x)");
  std::uint32_t tag = 0;
  std::uint64_t at = offset_;
  std::uint64_t len = read_section_header(tag);
  if (tag != kTagHead) fail(at, "expected the header section, found " + tag_name(tag));
  read_payload(payload_, len, "header");
  if (const std::string p = parse_head(payload_, header_); !p.empty()) fail(at + kSectionHeaderSize, p);
  header_.version_major = get_u16(pre + 8);
  sections_.push_back({kTagHead, kSectionCritical, at, len});

  at = offset_;
  len = read_section_header(tag);
  const std::uint64_t n = header_.point_count, rec = header_.point_record_bytes();
  if (tag != kTagPoints || len != n * rec) fail(at, "points section does not hold " + std::to_string(n) + " records");
  sections_.push_back({kTagPoints, kSectionCritical, at, len});
  // The points in chunks, their CRC over all of them; the ids kept when asked.
  if (keep_ids) ids_.resize(n);
  std::vector<std::uint8_t> chunk;
  std::uint32_t crc = 0;
  const std::size_t per_chunk = std::size_t(1) << 16;
  const std::size_t id_at = 3 * coord_bytes(header_.coord_type);
  for (std::uint64_t first = 0; first < n; first += per_chunk) {
    const std::size_t k = std::size_t(std::min<std::uint64_t>(per_chunk, n - first));
    chunk.resize(k * rec);
    read_exactly(chunk.data(), chunk.size(), "the points");
    crc = crc32c(chunk.data(), chunk.size(), crc);
    if (keep_ids)
      for (std::size_t i = 0; i < k; ++i) {
        const std::uint8_t* q = chunk.data() + i * rec + id_at;
        ids_[first + i] = header_.id_width == 32 ? get_u32(q) : get_u64(q);
      }
  }
  std::uint8_t stored[4];
  read_exactly(stored, 4, "the points' checksum");
  if (crc != get_u32(stored)) fail(at, "points: checksum mismatch (the stream is damaged)");
}

bool TetStreamReader::next_frame(std::vector<std::uint64_t>& labels) {
  if (done_) return false;
  for (;;) {
    const std::uint64_t at = offset_;
    std::uint32_t tag = 0;
    const std::uint64_t len = read_section_header(tag);
    const std::string what = "frame " + std::to_string(frames_.size());
    if (tag == kTagFrame) {
      read_payload(payload_, len, what);
      FrameHeader h;
      if (const std::string p = parse_frame_header(payload_, h); !p.empty())
        fail(at + kSectionHeaderSize, what + ": " + p);
      if (h.max_label >= header_.point_count) fail(at + kSectionHeaderSize, what + ": a label beyond the points");
      try {
        decoder_.decode(payload_, labels);
      } catch (const FrameError& e) {
        fail(at + kSectionHeaderSize + e.offset(), what + ": " + e.what());
      }
      frames_.push_back({at, tets_, h.tet_count, std::uint32_t(len), h.base_label, h.max_label});
      tets_ += h.tet_count;
      return true;
    }
    if (tag != kTagIndex) {  // a section this reader does not know and may skip
      read_payload(payload_, len, "section " + tag_name(tag));
      continue;
    }
    // The index and the footer must describe exactly what was streamed.
    read_payload(payload_, len, "index");
    std::vector<SectionEntry> sections;
    std::vector<FrameEntry> frames;
    if (const std::string p = parse_index(payload_, sections, frames); !p.empty()) fail(at + kSectionHeaderSize, p);
    bool same = frames.size() == frames_.size();
    for (std::size_t k = 0; same && k < frames.size(); ++k) {
      const FrameEntry &a = frames[k], &b = frames_[k];
      same = a.offset == b.offset && a.first_tet == b.first_tet && a.tet_count == b.tet_count && a.length == b.length &&
             a.base_label == b.base_label && a.max_label == b.max_label;
    }
    if (!same) fail(at, "the index does not describe the frames streamed before it");
    std::array<std::uint8_t, kFooterSize> footer_bytes;
    const std::uint64_t footer_at = offset_;
    read_exactly(footer_bytes.data(), footer_bytes.size(), "the footer");
    Footer footer;
    if (const std::string p = parse_footer(footer_bytes, footer); !p.empty()) fail(footer_at, p);
    if (footer.index_offset != at || footer.tet_count != tets_ || footer.frame_count != frames_.size() ||
        footer.point_count != header_.point_count)
      fail(footer_at, "the footer does not match the stream");
    std::uint8_t extra;
    ssize_t r;
    do r = ::read(fd_, &extra, 1);
    while (r < 0 && errno == EINTR);
    if (r > 0) fail(offset_, "bytes after the footer");
    done_ = true;
    return false;
  }
}

void TetStreamReader::map_to_original(std::span<std::uint64_t> labels) const {
  if (ids_.size() != header_.point_count) throw std::logic_error("TetStreamReader: ids were not kept");
  for (auto& l : labels) l = ids_[l];
}

}  // namespace tetstream::io
