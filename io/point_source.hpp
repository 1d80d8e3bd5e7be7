#pragma once
// A buffered, forward-only byte source over a file or stdin, for the point readers.
//
// Memory is bounded by the block size (8 MiB by default) whatever the file size: the
// buffer holds the unconsumed tail of the previous block plus one block of fresh
// bytes. Large contiguous reads (raw float64 in native order) bypass the buffer and
// read(2) straight into the caller's memory. We read with read(2) rather than mmap:
// a mapping counts every touched page of a 100 GB file in the process's resident set,
// and read(2) into one recycled buffer is as fast on sequential access.
//
// Offsets are absolute byte offsets in the input, for error messages.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

namespace tetstream::io {

class ByteSource {
 public:
  static constexpr std::size_t kDefaultBlock = std::size_t(8) << 20;

  // Opens `path` ("-" for stdin). Throws IoError when it cannot be opened.
  explicit ByteSource(const std::string& path, std::size_t block_bytes = kDefaultBlock);
  ~ByteSource();
  ByteSource(const ByteSource&) = delete;
  ByteSource& operator=(const ByteSource&) = delete;

  // The path, or "<stdin>": what error messages call the input.
  const std::string& name() const { return name_; }
  // Size in bytes of a regular file; nullopt for pipes and terminals.
  std::optional<std::uint64_t> size() const { return size_; }

  // Makes at least `n` bytes available at data() unless the input ends first; returns
  // available() (less than n only at the end of the input). Grows the buffer if needed.
  std::size_t ensure(std::size_t n);
  // Reads at least one more byte into the buffer unless at the end; returns available().
  std::size_t fill_more();

  const char* data() const { return buf_.get() + pos_; }
  std::size_t available() const { return end_ - pos_; }
  void consume(std::size_t n) { pos_ += n; }
  // Absolute offset of data() in the input.
  std::uint64_t offset() const { return base_ + pos_; }
  // True when nothing is buffered and the input has ended.
  bool at_end();

  // Copies up to `n` bytes to `dst`: first what is buffered, then straight from the
  // file. Returns fewer than n only at the end of the input.
  std::size_t read_into(void* dst, std::size_t n);
  // Skips `n` bytes (seeks on regular files). Returns the number skipped.
  std::uint64_t skip(std::uint64_t n);

 private:
  std::size_t read_some(char* dst, std::size_t n);  // one read(2), EINTR retried; 0 at EOF

  std::string name_;
  int fd_ = -1;
  bool own_fd_ = false;
  bool eof_ = false;
  std::optional<std::uint64_t> size_;
  std::unique_ptr<char[]> buf_;
  std::size_t cap_ = 0, pos_ = 0, end_ = 0;
  std::uint64_t base_ = 0;  // absolute offset of buf_[0]
};

}  // namespace tetstream::io
