#include "pipeline/files/temp_files.hpp"

#include "core/error.hpp"
#include "io/output_file.hpp"
#include "io/tet_container.hpp"

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <vector>
#include <fcntl.h>
#include <linux/falloc.h>
#include <sys/mman.h>
#include <unistd.h>

namespace tetstream::pipeline {

namespace {
std::string errno_text() { return std::strerror(errno); }
}  // namespace

void remove_file(const std::string& path) {
  std::error_code ec;
  std::filesystem::remove(path, ec);
}

void sync_directory(const std::string& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY);
  if (fd < 0) throw IoError(dir + ": cannot open: " + errno_text());
  const bool failed = ::fsync(fd) != 0;
  const int err = errno;
  ::close(fd);
  if (failed) {
    errno = err;
    throw IoError(dir + ": fsync failed: " + errno_text());
  }
}

void release_mapped_pages(const void* data, std::size_t bytes) {
  if (bytes == 0) return;
  const std::uintptr_t page = std::uintptr_t(sysconf(_SC_PAGESIZE));
  const auto begin = reinterpret_cast<std::uintptr_t>(data);
  const std::uintptr_t aligned = begin & ~(page - 1);
  madvise(reinterpret_cast<void*>(aligned), bytes + (begin - aligned), MADV_DONTNEED);
}

MappedRegions::MappedRegions(const void* data, std::size_t bytes, std::size_t max_regions, const std::string& path)
    : base_(static_cast<const char*>(data)),
      bytes_(bytes),
      max_regions_(std::max<std::size_t>(1, max_regions)),
      path_(path) {
  if (!path.empty()) {
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) throw IoError(path + ": cannot open: " + errno_text());
  }
  const std::size_t regions = (bytes >> kRegionShift) + 1;
  last_read_ = std::make_unique<std::atomic<std::uint64_t>[]>(regions);
  cold_reads_ = std::make_unique<std::atomic<std::uint64_t>[]>(regions);
  for (std::size_t r = 0; r < regions; ++r) {
    last_read_[r].store(0, std::memory_order_relaxed);
    cold_reads_[r].store(0, std::memory_order_relaxed);
  }
  held_.reserve(max_regions_ + 1);
}

MappedRegions::~MappedRegions() {
  if (fd_ >= 0) ::close(fd_);
}

void MappedRegions::read(const void* p, void* out, std::size_t bytes) {
  const std::size_t offset = std::size_t(static_cast<const char*>(p) - base_);
  if (fd_ >= 0 && !worth_mapping(offset >> kRegionShift)) {
    if (!io::pread_exactly(fd_, out, bytes, offset))
      throw IoError(path_ + ": read failed at offset " + std::to_string(offset) + ": " + errno_text());
    return;
  }
  touch(p);
  std::memcpy(out, p, bytes);
}

bool MappedRegions::worth_mapping(std::size_t r) {
  if (last_read_[r].load(std::memory_order_relaxed) != 0) return true;  // held
  // Not held: count the read in this stretch of epochs, and map the region once it
  // has been read often enough (a sweep through it) rather than here and there.
  const std::uint64_t now = clock_.load(std::memory_order_relaxed);
  std::uint64_t c = cold_reads_[r].load(std::memory_order_relaxed), next;
  do {
    const std::uint64_t since = c >> 24, count = c & 0xFFFFFF;
    next = since + max_regions_ >= now && count > 0 ? c + 1 : (now << 24 | 1);
  } while (!cold_reads_[r].compare_exchange_weak(c, next, std::memory_order_relaxed));
  if ((next & 0xFFFFFF) < kAdmitReads) return false;
  cold_reads_[r].store(0, std::memory_order_relaxed);
  return true;
}

void MappedRegions::hold(std::size_t region) {
  std::lock_guard lock(mutex_);
  const std::uint64_t now = clock_.fetch_add(1, std::memory_order_relaxed) + 1;
  if (last_read_[region].load(std::memory_order_relaxed) != 0) {  // another thread held it meanwhile
    last_read_[region].store(now, std::memory_order_relaxed);
    return;
  }
  if (held_.size() >= max_regions_) {
    // The least recently read: a linear scan, as there are few (and this runs once
    // per region faulted in, not per read).
    std::size_t oldest = 0;
    for (std::size_t i = 1; i < held_.size(); ++i)
      if (last_read_[held_[i]].load(std::memory_order_relaxed) <
          last_read_[held_[oldest]].load(std::memory_order_relaxed))
        oldest = i;
    release_region(held_[oldest]);
    held_[oldest] = held_.back();
    held_.pop_back();
  }
  last_read_[region].store(now, std::memory_order_relaxed);
  held_.push_back(region);
}

void MappedRegions::release_region(std::size_t r) {
  last_read_[r].store(0, std::memory_order_relaxed);
  const std::size_t first = r << kRegionShift;
  release_mapped_pages(base_ + first, std::min(kRegionBytes, bytes_ - first));
  releases_.fetch_add(1, std::memory_order_relaxed);
}

void MappedRegions::release_all() {
  std::lock_guard lock(mutex_);
  for (const std::size_t r : held_) release_region(r);
  held_.clear();
}

std::size_t MappedRegions::held() const {
  std::lock_guard lock(mutex_);
  return held_.size();
}

BinaryFile::BinaryFile(const std::string& path, const char* mode) : path_(path) {
  const std::string m = mode;
  if (m == "rb") {
    f_ = std::fopen(path.c_str(), "rb");
  } else if (m == "wb") {
    // A work file of the job's own directory: made new, never through a planted link.
    const int fd = io::create_work_file(path);
    f_ = ::fdopen(fd, "wb");
    if (!f_) ::close(fd);
  } else if (m == "r+b") {
    // A work file read once whose read part is given back (punching needs write
    // access): an existing file only, never through a link.
    const int fd = ::open(path.c_str(), O_RDWR | O_NOFOLLOW | O_CLOEXEC);
    if (fd >= 0) {
      f_ = ::fdopen(fd, "r+b");
      if (!f_) ::close(fd);
    }
  } else {
    throw std::logic_error("BinaryFile: mode " + m + " (rb, r+b or wb)");
  }
  if (!f_) throw IoError(path + ": cannot open: " + errno_text());
  std::setvbuf(f_, nullptr, _IOFBF, std::size_t(1) << 20);
}

BinaryFile::~BinaryFile() {
  if (f_) std::fclose(f_);
}

void BinaryFile::write(const void* data, std::size_t size, std::size_t count) {
  if (count == 0) return;
  if (std::fwrite(data, size, count, f_) != count) throw IoError(path_ + ": write failed: " + errno_text());
  crc_ = io::crc32c(data, size * count, crc_);
}

std::size_t BinaryFile::read(void* data, std::size_t size, std::size_t count) {
  const std::size_t n = std::fread(data, size, count, f_);
  if (n < count && std::ferror(f_)) throw IoError(path_ + ": read failed: " + errno_text());
  return n;
}

void BinaryFile::give_back_before(std::uint64_t offset) {
  offset &= ~std::uint64_t(4095);  // whole pages: a partial one would only be zeroed
  if (!f_ || !can_punch_ || offset <= given_back_) return;
  if (::fallocate(fileno(f_), FALLOC_FL_PUNCH_HOLE | FALLOC_FL_KEEP_SIZE, off_t(given_back_),
                  off_t(offset - given_back_)) != 0) {
    if (errno == EOPNOTSUPP || errno == ENOSYS) {
      can_punch_ = false;
      return;
    }
    throw IoError(path_ + ": cannot give back the read part: " + errno_text());
  }
  given_back_ = offset;
}

void BinaryFile::close(bool sync) {
  if (!f_) return;
  const bool failed = std::fflush(f_) != 0 || std::ferror(f_) || (sync && ::fsync(fileno(f_)) != 0);
  const int err = errno;
  const bool close_failed = std::fclose(f_) != 0;
  f_ = nullptr;
  if (failed || close_failed) {
    errno = err;
    throw IoError(path_ + ": write failed: " + errno_text());
  }
}

}  // namespace tetstream::pipeline
