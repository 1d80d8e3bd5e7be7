#include "io/output_file.hpp"

#include "core/error.hpp"

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace tetstream::io {

namespace {
[[noreturn]] void fail(const std::string& what, const std::string& path) {
  throw IoError(path + ": " + what + ": " + std::strerror(errno));
}
}  // namespace

OutputFile::OutputFile(std::string path, std::size_t buffer_bytes) : path_(std::move(path)) {
  partial_ = path_ + ".partial";
  fd_ = ::open(partial_.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd_ < 0) fail("cannot create", partial_);
  cap_ = std::max<std::size_t>(buffer_bytes, 4096);
  buf_.reset(new char[cap_]);
}

OutputFile::OutputFile(std::string path, std::size_t buffer_bytes, int fd, std::uint64_t flushed)
    : path_(std::move(path)), fd_(fd), flushed_(flushed) {
  partial_ = path_ + ".partial";
  cap_ = std::max<std::size_t>(buffer_bytes, 4096);
  buf_.reset(new char[cap_]);
}

std::unique_ptr<OutputFile> OutputFile::reopen(std::string path, std::uint64_t keep, std::size_t buffer_bytes) {
  const std::string partial = path + ".partial";
  const int fd = ::open(partial.c_str(), O_RDWR | O_CLOEXEC);
  if (fd < 0) fail("cannot reopen", partial);
  struct stat st;
  if (::fstat(fd, &st) != 0) {
    ::close(fd);
    fail("cannot stat", partial);
  }
  if (std::uint64_t(st.st_size) < keep) {
    ::close(fd);
    throw IoError(partial + ": has " + std::to_string(st.st_size) + " bytes, fewer than the " +
                  std::to_string(keep) + " to resume after");
  }
  if (::ftruncate(fd, off_t(keep)) != 0 || ::lseek(fd, off_t(keep), SEEK_SET) < 0) {
    ::close(fd);
    fail("cannot truncate", partial);
  }
  return std::unique_ptr<OutputFile>(new OutputFile(std::move(path), buffer_bytes, fd, keep));
}

OutputFile::~OutputFile() {
  if (fd_ >= 0) ::close(fd_);
  if (!committed_ && !keep_on_failure_) ::unlink(partial_.c_str());
}

void OutputFile::flush() {
  std::size_t done = 0;
  while (done < used_) {
    const ssize_t w = ::write(fd_, buf_.get() + done, used_ - done);
    if (w < 0) {
      if (errno == EINTR) continue;
      fail("write failed", partial_);
    }
    done += std::size_t(w);
  }
  flushed_ += used_;
  used_ = 0;
}

void OutputFile::write(const void* data, std::size_t n) {
  const char* p = static_cast<const char*>(data);
  if (used_ + n > cap_) {
    flush();
    if (n >= cap_) {  // large: straight through
      while (n > 0) {
        const ssize_t w = ::write(fd_, p, n);
        if (w < 0) {
          if (errno == EINTR) continue;
          fail("write failed", partial_);
        }
        p += w, n -= std::size_t(w), flushed_ += std::size_t(w);
      }
      return;
    }
  }
  std::memcpy(buf_.get() + used_, p, n);
  used_ += n;
}

char* OutputFile::reserve(std::size_t n) {
  if (used_ + n > cap_) flush();
  if (n > cap_) {
    // Larger than the buffer (a writer's fixed-size chunk with a small buffer_bytes):
    // grow it, now that it is empty, rather than hand out memory past its end.
    buf_.reset(new char[n]);
    cap_ = n;
  }
  return buf_.get() + used_;
}

void OutputFile::sync() {
  flush();
  if (::fsync(fd_) != 0) fail("fsync failed", partial_);
}

bool pread_exactly(int fd, void* data, std::size_t n, std::uint64_t offset) {
  char* p = static_cast<char*>(data);
  while (n > 0) {
    const ssize_t r = ::pread(fd, p, n, off_t(offset));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) {
      if (r == 0) errno = EIO;
      return false;
    }
    p += r, n -= std::size_t(r), offset += std::uint64_t(r);
  }
  return true;
}

void OutputFile::read_at(std::uint64_t offset, void* data, std::size_t n) const {
  if (!pread_exactly(fd_, data, n, offset)) fail("read back failed", partial_);
}

void OutputFile::commit(bool do_sync) {
  flush();
  if (do_sync && ::fsync(fd_) != 0) fail("fsync failed", partial_);
  if (::close(fd_) != 0) {
    fd_ = -1;
    fail("close failed", partial_);
  }
  fd_ = -1;
  if (::rename(partial_.c_str(), path_.c_str()) != 0) fail("cannot rename to " + path_, partial_);
  committed_ = true;
}

}  // namespace tetstream::io
