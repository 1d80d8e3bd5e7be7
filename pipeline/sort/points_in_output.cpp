#include "pipeline/sort/points_in_output.hpp"

#include "core/error.hpp"
#include "io/output_file.hpp"
#include "io/tet_writer.hpp"

#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <unistd.h>

namespace tetstream::pipeline {

namespace {
// As BinaryFile's stdio buffer, which the sort's memory share was measured with.
constexpr std::size_t kBufferBytes = std::size_t(1) << 20;

[[noreturn]] void fail(const std::string& path, const char* what) {
  throw IoError(path + ": " + what + ": " + std::strerror(errno));
}

}  // namespace

// From the end when moving towards the file's end, from the front when moving towards
// its start, so no byte is overwritten before it is read.
void move_file_bytes(int fd, const std::string& path, std::uint64_t from, std::uint64_t to, std::uint64_t n) {
  if (from == to) return;
  std::vector<char> chunk(kBufferBytes);
  for (std::uint64_t done = 0; done < n;) {
    const std::size_t k = std::size_t(std::min<std::uint64_t>(chunk.size(), n - done));
    const std::uint64_t at = to > from ? n - done - k : done;  // offset within the n bytes
    if (!io::pread_exactly(fd, chunk.data(), k, from + at)) fail(path, "read back failed");
    if (!io::pwrite_exactly(fd, chunk.data(), k, to + at)) fail(path, "write failed");
    done += k;
  }
}

std::vector<std::uint8_t> points_lead(const std::function<io::TetFileHeader(const SortedPoints&)>& header,
                                      const SortedPoints& points) {
  io::TetFileHeader h = header(points);
  h.resolve_and_validate();
  return io::leading_bytes(h);
}

std::uint64_t payload_offset_before_merge(const std::function<io::TetFileHeader(const SortedPoints&)>& header,
                                          const SortedPoints& before) {
  SortedPoints guess = before;
  guess.count = 1;  // a placeholder: N is a fixed-width field, the layout does not depend on it
  guess.duplicates = 0;
  return points_lead(header, guess).size();
}

PayloadWriter::PayloadWriter(int fd, std::string path, std::uint64_t offset)
    : fd_(fd), path_(std::move(path)), offset_(offset) {
  buffer_.reserve(kBufferBytes);
}

void PayloadWriter::write(const void* data, std::size_t bytes) {
  crc_ = io::crc32c(data, bytes, crc_);
  const char* p = static_cast<const char*>(data);
  while (bytes > 0) {
    const std::size_t n = std::min(bytes, kBufferBytes - buffer_.size());
    buffer_.insert(buffer_.end(), p, p + n);
    p += n, bytes -= n;
    written_ += n;
    if (buffer_.size() == kBufferBytes) flush();
  }
}

void PayloadWriter::flush() {
  const std::uint64_t at = offset_ + written_ - buffer_.size();
  if (!io::pwrite_exactly(fd_, buffer_.data(), buffer_.size(), at)) fail(path_, "write failed");
  buffer_.clear();
}

OutputPointsSink::OutputPointsSink(int fd, std::string partial_path,
                                   std::function<io::TetFileHeader(const SortedPoints&)> header,
                                   const SortedPoints& before)
    : header_(std::move(header)), payload_(fd, std::move(partial_path), payload_offset_before_merge(header_, before)) {}

void OutputPointsSink::write(const void* data, std::size_t bytes) { payload_.write(data, bytes); }

void OutputPointsSink::finish(SortedPoints& result, bool sync) {
  payload_.flush();
  const std::vector<std::uint8_t> lead = points_lead(header_, result);
  // The header was laid out with no duplicates: the real count has at least as many digits.
  if (lead.size() < payload_.offset()) throw std::logic_error("OutputPointsSink: the header shrank");
  const int fd = payload_.fd();
  const std::string& path = payload_.path();
  move_file_bytes(fd, path, payload_.offset(), lead.size(), payload_.written());
  std::uint8_t crc[4];
  io::put_u32(crc, payload_.crc());
  if (!io::pwrite_exactly(fd, lead.data(), lead.size(), 0) ||
      !io::pwrite_exactly(fd, crc, 4, lead.size() + payload_.written()))
    fail(path, "write failed");
  if (sync && ::fsync(fd) != 0) fail(path, "write failed");
  result.path = path;
  result.offset = lead.size();
  result.crc32c = payload_.crc();
}

void rewrite_points_header(int fd, SortedPoints& points, const io::TetFileHeader& header, bool sync) {
  io::TetFileHeader h = header;
  h.resolve_and_validate();
  const std::vector<std::uint8_t> lead = io::leading_bytes(h);
  // The records and the CRC after them.
  move_file_bytes(fd, points.path, points.offset, lead.size(),
                  points.count * points.layout.bytes() + io::kSectionTrailerSize);
  if (!io::pwrite_exactly(fd, lead.data(), lead.size(), 0)) fail(points.path, "write failed");
  if (sync && ::fsync(fd) != 0) fail(points.path, "write failed");
  points.offset = lead.size();
}

}  // namespace tetstream::pipeline
