#include "io/output_file.hpp"

#include "core/error.hpp"

#include <atomic>
#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <set>
#include <stdexcept>
#include <utility>
#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

namespace tetstream::io {

namespace {
[[noreturn]] void fail(const std::string& what, const std::string& path) {
  throw IoError(path + ": " + what + ": " + std::strerror(errno));
}
}  // namespace

namespace {
using FileId = std::pair<std::uint64_t, std::uint64_t>;
std::mutex& noted_mutex() {
  static std::mutex m;
  return m;
}
std::set<FileId>& noted() {
  static std::set<FileId> s;
  return s;
}
std::atomic<bool>& noting() {
  static std::atomic<bool> on{false};
  return on;
}
void note(const struct stat& st) {
  if (!noting().load(std::memory_order_relaxed) || !S_ISREG(st.st_mode)) return;
  std::lock_guard lock(noted_mutex());
  noted().insert({std::uint64_t(st.st_dev), std::uint64_t(st.st_ino)});
}
bool is_noted(const struct stat& st) {
  if (!noting().load(std::memory_order_relaxed)) return false;
  std::lock_guard lock(noted_mutex());
  return noted().count({std::uint64_t(st.st_dev), std::uint64_t(st.st_ino)}) != 0;
}
}  // namespace

void note_input(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0) note(st);
}

void note_input_fd(int fd) {
  struct stat st {};
  if (fd >= 0 && ::fstat(fd, &st) == 0) note(st);
}

void note_files(bool on) { noting().store(on, std::memory_order_relaxed); }

void forget_noted_files() {
  std::lock_guard lock(noted_mutex());
  noted().clear();
}

bool is_noted_input(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && is_noted(st);
}

void refuse_stdout_into_input() {
  struct stat st {};
  if (::fstat(STDOUT_FILENO, &st) == 0 && S_ISREG(st.st_mode) && is_noted(st))
    throw UsageError("standard output is a file this command reads: refusing to write into its own input");
}

int create_work_file(const std::string& path, int flags) {
  if (::unlink(path.c_str()) != 0 && errno != ENOENT) fail("cannot remove the old work file", path);
  const int fd = ::open(path.c_str(), flags | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0600);
  if (fd < 0) fail("cannot create", path);
  return fd;
}

int open_work_file(const std::string& path) {
  int fd = ::open(path.c_str(), O_RDWR | O_NOFOLLOW | O_CLOEXEC);
  if (fd < 0 && errno == ENOENT) fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0600);
  if (fd < 0) fail("cannot open", path);
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    throw IoError(path + ": not a regular file");
  }
  return fd;
}

void check_output_path(const std::string& path) {
  struct stat st {};
  if (::lstat(path.c_str(), &st) != 0) {
    if (errno == ENOENT) return;
    fail("cannot stat", path);
  }
  if (S_ISLNK(st.st_mode))
    throw UsageError(path + " is a symbolic link: tetstream does not write through links (give the real path)");
  if (S_ISDIR(st.st_mode)) throw UsageError(path + " is a directory: give the output file's name");
  if (!S_ISREG(st.st_mode))
    throw UsageError(path +
                     " is not a regular file (a device, pipe or socket): tetstream writes regular files, "
                     "or - for standard output where the command supports it");
  if (is_noted(st)) throw UsageError(path + " is a file this command reads or has written: refusing to write over it");
}

void refuse_input_as_output(const std::string& input, const std::string& output) {
  struct stat in {};
  if (::stat(input.c_str(), &in) != 0 || !S_ISREG(in.st_mode)) return;
  for (const std::string& p : {output, output + ".partial"}) {
    struct stat st {};
    if (::lstat(p.c_str(), &st) == 0 && st.st_dev == in.st_dev && st.st_ino == in.st_ino)
      throw UsageError("the output " + p + " is the input " + input + ": refusing to write over the input");
  }
}

OutputClaim::OutputClaim(std::string path, Kind kind, const std::string& main)
    : path_(std::move(path)), partial_(path_ + ".partial") {
  check_output_path(path_);
  struct stat existing {};
  if (kind == Kind::kBeside && ::lstat(path_.c_str(), &existing) == 0 && ::lstat(main.c_str(), &existing) != 0)
    throw UsageError(path_ + " exists and is not an earlier output beside " + main +
                     ": refusing to replace it (move it, or choose another output name)");
  fd_ = ::open(partial_.c_str(), O_RDWR | O_CLOEXEC | O_NOFOLLOW);
  if (fd_ < 0 && errno == ENOENT) {
    fd_ = ::open(partial_.c_str(), O_RDWR | O_CLOEXEC | O_NOFOLLOW | O_CREAT | O_EXCL, 0644);
    created_ = fd_ >= 0;
  }
  if (fd_ < 0) {
    if (errno == ELOOP) throw UsageError(partial_ + " is a symbolic link: tetstream does not follow it (remove it)");
    fail("cannot create", partial_);
  }
  struct stat st {};
  if (::fstat(fd_, &st) != 0) fail("cannot stat", partial_);
  if (!created_ && S_ISREG(st.st_mode) && is_noted(st)) {
    ::close(fd_);
    fd_ = -1;
    throw UsageError(partial_ + " is a file this command reads: refusing to write over it");
  }
  if (!S_ISREG(st.st_mode) || st.st_nlink != 1) {
    ::close(fd_);
    fd_ = -1;
    throw UsageError(partial_ +
                     " is not a regular file of its own (a device, pipe, or a hard link to another file): "
                     "remove it");
  }
  if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    ::close(fd_);
    fd_ = -1;
    errno = err;
    if (err == EWOULDBLOCK) throw UsageError(path_ + " is being written by another tetstream process");
    fail("cannot lock", partial_);
  }
}

OutputClaim::~OutputClaim() {
  if (fd_ < 0) return;
  struct stat st {};
  // Still linked (not renamed into place, not removed by the writer) and empty: the
  // job wrote nothing, and the file is the one this claim made.
  if (created_ && ::fstat(fd_, &st) == 0 && st.st_nlink > 0 && st.st_size == 0) {
    struct stat at {};
    if (::lstat(partial_.c_str(), &at) == 0 && at.st_ino == st.st_ino && at.st_dev == st.st_dev)
      ::unlink(partial_.c_str());
  }
  ::close(fd_);
}

namespace {
// A descriptor of PATH.partial that shares the claim's lock (the same open file).
int claimed_fd(const OutputClaim& claim) {
  const int fd = ::fcntl(claim.fd(), F_DUPFD_CLOEXEC, 0);
  if (fd < 0) fail("cannot duplicate the descriptor of", claim.path() + ".partial");
  return fd;
}
}  // namespace

OutputFile::OutputFile(std::string path, std::size_t buffer_bytes, const OutputClaim* claim) : path_(std::move(path)) {
  partial_ = path_ + ".partial";
  if (!claim) own_claim_ = std::make_unique<OutputClaim>(path_), claim = own_claim_.get();
  fd_ = claimed_fd(*claim);
  if (::ftruncate(fd_, 0) != 0 || ::lseek(fd_, 0, SEEK_SET) < 0) fail("cannot truncate", partial_);
  cap_ = std::max<std::size_t>(buffer_bytes, 4096);
  buf_.reset(new char[cap_]);
}

OutputFile::OutputFile(std::string path, std::size_t buffer_bytes, int fd, std::uint64_t flushed)
    : path_(std::move(path)), fd_(fd), flushed_(flushed) {
  partial_ = path_ + ".partial";
  cap_ = std::max<std::size_t>(buffer_bytes, 4096);
  buf_.reset(new char[cap_]);
}

std::unique_ptr<OutputFile> OutputFile::reopen(std::string path, std::uint64_t keep, std::size_t buffer_bytes,
                                               const OutputClaim* claim) {
  const std::string partial = path + ".partial";
  std::unique_ptr<OutputClaim> own;
  if (!claim) own = std::make_unique<OutputClaim>(path), claim = own.get();
  const int fd = claimed_fd(*claim);
  struct stat st;
  if (::fstat(fd, &st) != 0) {
    ::close(fd);
    fail("cannot stat", partial);
  }
  if (std::uint64_t(st.st_size) < keep) {
    ::close(fd);
    throw IoError(partial + ": has " + std::to_string(st.st_size) + " bytes, fewer than the " + std::to_string(keep) +
                  " to resume after");
  }
  if (::ftruncate(fd, off_t(keep)) != 0 || ::lseek(fd, off_t(keep), SEEK_SET) < 0) {
    ::close(fd);
    fail("cannot truncate", partial);
  }
  std::unique_ptr<OutputFile> f(new OutputFile(std::move(path), buffer_bytes, fd, keep));
  f->own_claim_ = std::move(own);
  return f;
}

std::unique_ptr<OutputFile> OutputFile::to_stdout(std::size_t buffer_bytes) {
  if (::isatty(STDOUT_FILENO))
    throw UsageError("-o -: standard output is a terminal; pipe it into a command or a file");
  refuse_stdout_into_input();
  const int fd = ::fcntl(STDOUT_FILENO, F_DUPFD_CLOEXEC, 0);
  if (fd < 0) fail("cannot duplicate", "standard output");
  std::unique_ptr<OutputFile> f(new OutputFile("-", buffer_bytes, fd, 0));
  f->stream_ = true;
  f->partial_ = "standard output";
  return f;
}

OutputFile::~OutputFile() {
  if (fd_ >= 0) ::close(fd_);
  if (!committed_ && !keep_on_failure_ && !stream_) ::unlink(partial_.c_str());
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
  if (n == 0) return;  // callers pass empty vectors, whose data() may be null
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
  if (!stream_ && ::fsync(fd_) != 0) fail("fsync failed", partial_);
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

bool pwrite_exactly(int fd, const void* data, std::size_t n, std::uint64_t offset) {
  const char* p = static_cast<const char*>(data);
  while (n > 0) {
    const ssize_t w = ::pwrite(fd, p, n, off_t(offset));
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) {
      if (w == 0) errno = EIO;
      return false;
    }
    p += w, n -= std::size_t(w), offset += std::uint64_t(w);
  }
  return true;
}

void OutputFile::write_at(std::uint64_t offset, const void* data, std::size_t n) {
  if (stream_) throw std::logic_error("OutputFile: standard output cannot be rewritten");
  if (offset + n > this->offset()) throw std::logic_error("OutputFile::write_at past the end");
  flush();
  if (!pwrite_exactly(fd_, data, n, offset)) fail("write failed", partial_);
}

void OutputFile::skip(std::uint64_t n) {
  if (stream_) throw std::logic_error("OutputFile: standard output cannot skip");
  flush();
  struct stat st {};
  if (::fstat(fd_, &st) != 0) fail("stat failed", partial_);
  if (std::uint64_t(st.st_size) < flushed_ + n)
    throw IoError(partial_ + ": " + std::to_string(flushed_ + n) + " bytes expected, " + std::to_string(st.st_size) +
                  " found (another process's part is missing)");
  flushed_ += n;
  if (::lseek(fd_, off_t(flushed_), SEEK_SET) < 0) fail("seek failed", partial_);
}

void OutputFile::read_at(std::uint64_t offset, void* data, std::size_t n) const {
  if (stream_) throw std::logic_error("OutputFile: standard output cannot be read back");
  if (!pread_exactly(fd_, data, n, offset)) fail("read back failed", partial_);
}

void OutputFile::discard() {
  if (stream_) throw std::logic_error("OutputFile: discard on standard output");
  used_ = 0;
  flushed_ = 0;
  if (::ftruncate(fd_, 0) != 0) fail("cannot truncate", partial_);
  keep_on_failure_ = true;
}

void OutputFile::commit(bool do_sync) {
  flush();
  if (stream_) {
    ::close(fd_);
    fd_ = -1;
    committed_ = true;
    return;
  }
  if (do_sync && ::fsync(fd_) != 0) fail("fsync failed", partial_);
  if (::close(fd_) != 0) {
    fd_ = -1;
    fail("close failed", partial_);
  }
  fd_ = -1;
  struct stat done {};
  const bool known = ::lstat(partial_.c_str(), &done) == 0;
  if (::rename(partial_.c_str(), path_.c_str()) != 0) fail("cannot rename to " + path_, partial_);
  if (known) note(done);  // a later output of this process (--json-file) never replaces it
  committed_ = true;
}

}  // namespace tetstream::io

namespace tetstream::io {

OutputPart::OutputPart(const std::string& partial_path, Identity identity) : path_(partial_path) {
  fd_ = ::open(path_.c_str(), O_RDWR | O_NOFOLLOW | O_CLOEXEC);
  if (fd_ < 0) throw IoError(path_ + ": cannot open the output being written: " + std::strerror(errno));
  struct stat st {};
  if (::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode) ||
      Identity{std::uint64_t(st.st_dev), std::uint64_t(st.st_ino)} != identity) {
    ::close(fd_);
    throw IoError(path_ + ": not the file this job is writing (it was replaced)");
  }
}

OutputPart::~OutputPart() { ::close(fd_); }

void OutputPart::write_at(const void* data, std::size_t n, std::uint64_t offset) {
  if (!pwrite_exactly(fd_, data, n, offset)) throw IoError(path_ + ": write failed: " + std::strerror(errno));
}

void OutputPart::sync() {
  if (::fdatasync(fd_) != 0) throw IoError(path_ + ": fdatasync failed: " + std::strerror(errno));
}

OutputPart::Identity OutputPart::identity_of(int fd) {
  struct stat st {};
  if (::fstat(fd, &st) != 0) throw IoError(std::string("fstat failed: ") + std::strerror(errno));
  return {std::uint64_t(st.st_dev), std::uint64_t(st.st_ino)};
}

}  // namespace tetstream::io
