#include "pipeline/run/disk_plan.hpp"

#include "core/error.hpp"
#include "pipeline/sort/point_record.hpp"
#include "pipeline/util/progress.hpp"

#include <cerrno>
#include <algorithm>
#include <cstring>
#include <sys/stat.h>
#include <sys/statvfs.h>

namespace tetstream::pipeline {

namespace {

constexpr std::uint64_t kTetBytesPerPoint = 4 * 7;
constexpr std::uint64_t kMergeSlack = std::uint64_t(64) << 20;

struct Filesystem {
  dev_t device;
  std::uint64_t available;
};

Filesystem examine(const std::string& dir) {
  struct stat st {};
  struct statvfs vfs {};
  if (::stat(dir.c_str(), &st) != 0 || ::statvfs(dir.c_str(), &vfs) != 0)
    throw IoError(dir + ": cannot examine the filesystem: " + std::strerror(errno));
  return {st.st_dev, std::uint64_t(vfs.f_bavail) * std::uint64_t(vfs.f_frsize)};
}

}  // namespace

std::uint64_t distributed_work_bytes_per_point(int ranks) {
  const std::uint64_t k = std::uint64_t(std::max(ranks, 1));
  return 8 + (kTetBytesPerPoint * (k - 1) + k - 1) / k;
}

std::vector<DiskNeed> plan_disk(std::uint64_t points, bool float32, const std::string& work_parent,
                                const std::string& output_dir, bool output_to_stdout, bool checkpointed,
                                std::uint64_t more_work) {
  const std::uint64_t record = RecordLayout::for_input(float32, points).bytes();
  const std::uint64_t sorted = points * record;
  const std::uint64_t merge = sorted + sorted / 64 + kMergeSlack;  // runs given back as the merge reads them
  const std::uint64_t tets = points * kTetBytesPerPoint;
  const std::uint64_t pending =
      checkpointed ? 2 * 32 * std::min<std::uint64_t>(7 * points, (std::uint64_t(1) << 18) + 4096) + (1 << 20) : 0;
  const std::uint64_t extra = points * more_work;  // held through the triangulation, beside the output
  const Filesystem work = examine(work_parent);
  // Standard output: the sorted points are a work file, the output takes no disk.
  if (output_to_stdout) return {{work_parent, merge + extra, work.available}};
  const Filesystem out = examine(output_dir);
  if (out.device == work.device)
    return {{work_parent, std::max(merge, sorted + tets + pending + extra), work.available}};
  return {{work_parent, std::max(merge, pending + extra), work.available}, {output_dir, sorted + tets, out.available}};
}

void check_disk(const std::vector<DiskNeed>& plan) {
  std::string problems;
  for (const DiskNeed& d : plan)
    if (d.need > d.available)
      problems += (problems.empty() ? "" : "; ") + std::string("needs ") + human_bytes(double(d.need)) + " in " +
                  d.dir + ", " + human_bytes(double(d.available)) + " free";
  if (!problems.empty())
    throw IoError("not enough disk for this job: " + problems +
                  " (free space, or put the work files elsewhere with --tmpdir)");
}

}  // namespace tetstream::pipeline
