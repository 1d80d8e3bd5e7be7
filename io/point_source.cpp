#include "io/point_source.hpp"
#include "io/output_file.hpp"

#include "core/error.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace tetstream::io {

ByteSource::ByteSource(const std::string& path, std::size_t block_bytes) {
  if (path == "-") {
    name_ = "<stdin>";
    fd_ = STDIN_FILENO;
  } else {
    name_ = path;
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) throw IoError("cannot open " + path + ": " + std::strerror(errno));
    own_fd_ = true;
    note_input_fd(fd_);
  }
  struct stat st {};
  if (::fstat(fd_, &st) == 0 && S_ISREG(st.st_mode)) {
    size_ = static_cast<std::uint64_t>(st.st_size);
#ifdef POSIX_FADV_SEQUENTIAL
    ::posix_fadvise(fd_, 0, 0, POSIX_FADV_SEQUENTIAL);
#endif
  } else if (own_fd_ && S_ISDIR(st.st_mode)) {
    ::close(fd_);
    throw IoError("cannot read " + path + ": is a directory");
  }
  cap_ = block_bytes < 4096 ? 4096 : block_bytes;
  buf_.reset(new char[cap_]);
}

ByteSource::~ByteSource() {
  if (own_fd_) ::close(fd_);
}

std::size_t ByteSource::read_some(char* dst, std::size_t n) {
  for (;;) {
    const ssize_t r = ::read(fd_, dst, n);
    if (r >= 0) {
      if (r == 0) eof_ = true;
      return static_cast<std::size_t>(r);
    }
    if (errno == EINTR) continue;
    throw IoError("cannot read " + name_ + " at byte " + std::to_string(offset()) + ": " + std::strerror(errno));
  }
}

std::size_t ByteSource::ensure(std::size_t n) {
  if (available() >= n || eof_) return available();
  // Move the unconsumed tail to the front, grow if one block cannot hold n bytes.
  const std::size_t tail = available();
  if (n > cap_) {
    std::size_t cap = cap_;
    while (cap < n) cap *= 2;
    std::unique_ptr<char[]> bigger(new char[cap]);
    std::memcpy(bigger.get(), buf_.get() + pos_, tail);
    buf_ = std::move(bigger);
    cap_ = cap;
  } else if (pos_ > 0) {
    std::memmove(buf_.get(), buf_.get() + pos_, tail);
  }
  base_ += pos_;
  pos_ = 0;
  end_ = tail;
  // Fill the whole block: few large reads are what makes sequential input fast.
  while (end_ < cap_ && !eof_) {
    const std::size_t r = read_some(buf_.get() + end_, cap_ - end_);
    end_ += r;
    if (end_ >= n && r == 0) break;
  }
  return available();
}

std::size_t ByteSource::fill_more() {
  if (eof_) return available();
  return ensure(available() + 1);
}

bool ByteSource::at_end() {
  if (available() > 0) return false;
  return ensure(1) == 0;
}

std::size_t ByteSource::read_into(void* dst, std::size_t n) {
  char* out = static_cast<char*>(dst);
  const std::size_t buffered = available() < n ? available() : n;
  std::memcpy(out, data(), buffered);
  consume(buffered);
  std::size_t done = buffered;
  // The buffer is empty now (or n was satisfied); read the rest directly.
  while (done < n && !eof_) {
    const std::size_t r = read_some(out + done, n - done);
    done += r;
    base_ += r;  // the bytes went past the (empty) buffer: advance its base
  }
  return done;
}

std::uint64_t ByteSource::skip(std::uint64_t n) {
  const std::uint64_t buffered = available() < n ? available() : n;
  consume(static_cast<std::size_t>(buffered));
  std::uint64_t done = buffered;
  if (done == n) return done;
  if (size_) {
    // Regular file: seek, clamped to the end so offsets stay truthful.
    const std::uint64_t here = offset();
    const std::uint64_t want = here + (n - done);
    const std::uint64_t to = want < *size_ ? want : *size_;
    if (::lseek(fd_, static_cast<off_t>(to), SEEK_SET) < 0)
      throw IoError("cannot seek in " + name_ + ": " + std::strerror(errno));
    base_ = to;
    pos_ = end_ = 0;
    if (to == *size_) eof_ = true;
    return done + (to - here);
  }
  while (done < n) {
    const std::size_t want = static_cast<std::size_t>(std::min<std::uint64_t>(n - done, cap_));
    if (ensure(want) == 0) break;
    const std::size_t take = std::min<std::size_t>(available(), want);
    consume(take);
    done += take;
  }
  return done;
}

}  // namespace tetstream::io
