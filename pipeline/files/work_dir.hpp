#pragma once
// A directory of a job's working files that the job made itself (docs/safety.md).
//
// The user's files are next door: a checkpoint or temporary directory lives beside
// the output or in a directory the user named, and the job must never remove
// anything it did not create. So a WorkDir
//   - is always a directory the job created (mkdir or mkdtemp), never one that
//     existed: an existing path is reopened only when it is a real directory (not a
//     symbolic link) of this user that holds the marker file written at creation;
//   - is locked while a process works in it (flock on DIR/lock, released by the
//     kernel when the process dies), so a second process is refused, and a directory
//     whose lock is free belongs to a dead job;
//   - is emptied file by file: only regular files and links directly inside it whose
//     names are those the job writes (is_work_file_name) are unlinked (a link itself, never its
//     target), it never recurses, and the directory is removed with rmdir, which
//     leaves it in place when anything else is in it.
// Order of creation: directory, lock (taken), marker. A directory with a marker has
// had its lock taken before, so `tetstream clean` cannot take a live job's directory
// for a dead one. A named directory (open_or_create) is made so under PATH.new-XXXXXX
// and renamed to PATH once marked, and removed by renaming it aside first
// (DIR.old-PID-N), then state, files, lock, marker: PATH never exists unmarked or half
// removed, whenever the process is killed.
#include <string>
#include <vector>

namespace tetstream::pipeline {

class WorkDir {
 public:
  static constexpr const char* kMarker = ".tetstream-workdir";
  static constexpr const char* kLock = "lock";

  // Makes PARENT/PREFIX-XXXXXX (mkdtemp, mode 0700), locked and marked. Throws IoError.
  static WorkDir create_unique(const std::string& parent, const std::string& prefix);
  // Opens PATH when it is a work directory made by tetstream (the marker is in it),
  // or makes it when it does not exist (its parent must). Takes the lock: UsageError
  // when another process holds it, or when PATH exists but is a link, not a
  // directory, another user's, or has no marker (then tetstream did not make it).
  static WorkDir open_or_create(const std::string& path);

  WorkDir(WorkDir&& other) noexcept;
  WorkDir& operator=(WorkDir&&) = delete;
  WorkDir(const WorkDir&) = delete;
  ~WorkDir();  // releases the lock; removes nothing

  const std::string& dir() const { return dir_; }
  std::string path(const std::string& name) const { return dir_ + "/" + name; }

  // Unlinks the owned files but the lock and the marker (--force starting over).
  void clear() const;
  // Unlinks every owned file, the marker and the lock, then rmdir. Never throws;
  // returns false (and leaves the directory) when something not owned is left in it.
  bool remove() noexcept;

 private:
  explicit WorkDir(std::string dir) : dir_(std::move(dir)) {}
  void lock_or_refuse();
  void remove_owned(bool keep_lock_and_marker) const;
  bool move_aside() noexcept;

  std::string dir_;
  int lock_fd_ = -1;
};

// A stale work directory: made by tetstream (marker), no process holds its lock.
struct StaleWorkDir {
  std::string path;
  bool checkpoint = false;  // holds a checkpoint's state.json (resumable work)
};
// The stale work directories directly inside `parent` (not following links).
std::vector<StaleWorkDir> find_stale_work_dirs(const std::string& parent);
// Removes a stale directory found above, after taking its lock (a job that started in
// between keeps it). False when it could not.
bool remove_stale_work_dir(const StaleWorkDir& stale);

// The names of the files a job writes in its work directory: state.json, the sort's
// and verify's runs (NAME-K.run, NAME-K.run.hull; a rank's: rank-R-NAME-K.run),
// sorted.points, hull.labels, stdin.f64, pending-S.tets, index.shared (the point index
// on disk: the ranks of a job share it, and one process keeps it there with --index
// disk), rank-R.progress (a rank's count for rank 0's progress
// line), a periodic job's files (periodic-*: docs/periodic.md), and the .tmp of each
// while it is written atomically.
bool is_work_file_name(const std::string& name);
// The rank R of a work file that rank R of a job under mpirun wrote (rank-R.json,
// rank-R.tets, rank-R-pending-S.tets, rank-R.progress, rank-R-NAME-K.run, ...); -1 for
// the others (rank 0's files carry no rank).
int work_file_rank(const std::string& name);

}  // namespace tetstream::pipeline
