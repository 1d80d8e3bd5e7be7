#include "pipeline/util/disk_meter.hpp"

#include <dirent.h>
#include <fcntl.h>
#include <sys/stat.h>

#include <algorithm>

namespace tetstream::pipeline {

namespace {

// Bytes allocated to a regular file (0 when it is missing or not a regular file).
std::uint64_t allocated(int dir_fd, const char* name) {
  struct stat st {};
  if (::fstatat(dir_fd, name, &st, AT_SYMLINK_NOFOLLOW) != 0 || !S_ISREG(st.st_mode)) return 0;
  return std::uint64_t(st.st_blocks) * 512;
}

}  // namespace

std::uint64_t DiskMeter::sample() {
  std::uint64_t total = 0;
  if (DIR* d = ::opendir(dir_.c_str())) {
    while (const dirent* e = ::readdir(d)) total += allocated(::dirfd(d), e->d_name);
    ::closedir(d);
  }
  if (!output_partial_.empty()) total += allocated(AT_FDCWD, output_partial_.c_str());
  std::lock_guard lock(mutex_);
  peak_ = std::max(peak_, total);
  return total;
}

}  // namespace tetstream::pipeline
