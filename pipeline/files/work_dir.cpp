#include "pipeline/files/work_dir.hpp"

#include "core/error.hpp"
#include "io/output_file.hpp"
#include "io/tet_container.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <fstream>

#include <cstdint>
#include <ctime>

#include <cerrno>
#include <cstring>
#include <regex>
#include <vector>
#include <dirent.h>
#include <fcntl.h>
#include <sys/file.h>
#include <stdio.h>  // renameat2
#include <sys/stat.h>
#include <unistd.h>

namespace tetstream::pipeline {

namespace {

std::string errno_text() { return std::strerror(errno); }

// Opens (creating) DIR/lock and takes it without waiting. The fd, or -1 with errno
// EWOULDBLOCK when another process holds it. O_NOFOLLOW: a planted link is refused.
int try_lock(const std::string& dir, bool create) {
  const std::string lock = dir + "/" + WorkDir::kLock;
  int fd = -1;
  if (create) {
    try {
      fd = io::open_work_file(lock);
    } catch (const IoError&) {
      if (errno == 0) errno = EINVAL;
      return -1;
    }
  } else {
    fd = ::open(lock.c_str(), O_RDWR | O_CLOEXEC | O_NOFOLLOW);
  }
  if (fd < 0) return -1;
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    ::close(fd);
    errno = err;
    return -1;
  }
  return fd;
}

// The line of the marker that names the directory it was made in: its device and
// inode. A copy of the marker (a checkpoint copied elsewhere, a marker dropped into a
// directory of the user's) sits in a directory with another inode, and is not taken
// for a work directory.
std::string identity_line(const struct stat& dir) {
  return "directory " + std::to_string(std::uint64_t(dir.st_dev)) + ":" + std::to_string(std::uint64_t(dir.st_ino));
}

// PATH is a real directory (lstat: not a link) of this user holding a marker written
// in this very directory.
bool is_own_work_dir(const std::string& path) {
  struct stat st {};
  if (::lstat(path.c_str(), &st) != 0 || !S_ISDIR(st.st_mode) || st.st_uid != ::geteuid()) return false;
  const std::string m = path + "/" + WorkDir::kMarker;
  const int fd = ::open(m.c_str(), O_RDONLY | O_NOFOLLOW | O_CLOEXEC);
  if (fd < 0) return false;
  struct stat marker {};
  char buf[4096];
  ssize_t n = -1;
  if (::fstat(fd, &marker) == 0 && S_ISREG(marker.st_mode) && marker.st_uid == ::geteuid())
    n = ::read(fd, buf, sizeof buf);
  ::close(fd);
  if (n <= 0) return false;
  const std::string text(buf, std::size_t(n));
  std::string want = identity_line(st);
  want.insert(want.begin(), '\n');
  want.push_back('\n');
  return text.find(want) != std::string::npos;
}

void write_marker(const std::string& dir, const std::string& shown_path) {
  struct stat st {};
  if (::lstat(dir.c_str(), &st) != 0 || !S_ISDIR(st.st_mode)) throw IoError(dir + ": cannot stat: " + errno_text());
  const std::string m = dir + "/" + WorkDir::kMarker;
  const int fd = io::create_work_file(m);
  char host[256] = {};
  ::gethostname(host, sizeof host - 1);
  const std::string text = "made by tetstream: its working files; removed when the job ends\n" + identity_line(st) +
                           "\npath " + shown_path + "\njob " + std::to_string(::getpid()) + "@" + host + " " +
                           std::to_string(std::time(nullptr)) + "\n";
  const bool ok = ::write(fd, text.data(), text.size()) == ssize_t(text.size()) && ::fsync(fd) == 0;
  ::close(fd);
  if (!ok) throw IoError(m + ": cannot write: " + errno_text());
}

}  // namespace

bool is_work_file_name(const std::string& name) {
  static const std::regex kNames(
      R"((state\.json|rank-[0-9]+\.json|rank-[0-9]+\.progress|neighbour-rows\.u32|sorted\.points|hull\.labels|stdin\.f64|rho-by-label\.f64|index\.shared|(rank-[0-9]+-)?[a-z]+(-[a-z]+)*-[0-9]+\.run(\.hull)?|(rank-[0-9]+-)?pending-[0-9]+\.tets)(\.tmp)?|(rank-[0-9]+-)?label-order\.u32|rank-[0-9]+\.tets(\.partial)?|periodic-(points|images)\.f64(\.tmp)?|periodic-(padded|unwrapped)\.tets(\.partial)?|periodic-(deferred|offsets)\.tets|periodic-(pending|waiting)-[0-9]+\.tets(\.tmp)?)");
  return std::regex_match(name, kNames);
}

int work_file_rank(const std::string& name) {
  static const std::regex kRank(R"(rank-([0-9]{1,9})[-.].*)");
  std::smatch m;
  if (!is_work_file_name(name) || !std::regex_match(name, m, kRank)) return -1;
  return std::stoi(m[1].str());
}

WorkDir WorkDir::create_unique(const std::string& parent, const std::string& prefix) {
  std::string templ = (parent.empty() ? std::string(".") : parent) + "/" + prefix + "-XXXXXX";
  std::vector<char> buf(templ.begin(), templ.end());
  buf.push_back('\0');
  if (!::mkdtemp(buf.data())) throw IoError("cannot create a temporary directory in " + parent + ": " + errno_text());
  WorkDir w(buf.data());
  w.lock_or_refuse();
  write_marker(w.dir_, w.dir_);
  return w;
}

WorkDir WorkDir::open_or_create(const std::string& path) {
  WorkDir w(path);
  struct stat st {};
  if (::lstat(path.c_str(), &st) != 0) {
    if (errno != ENOENT) throw IoError(path + ": cannot stat: " + errno_text());
    // Made complete under a unique name beside PATH (directory, lock, marker), then
    // renamed to PATH: a process killed while making it leaves no unmarked PATH that
    // --resume would have to refuse as not tetstream's (a SIGKILL between mkdir and the
    // marker did that), only PATH.new-XXXXXX, which `tetstream clean` removes once
    // marked. Not its parents: a mistyped --tmpdir is an error, not a tree of new
    // directories.
    const std::string::size_type slash = path.rfind('/');
    const std::string parent = slash == std::string::npos ? "." : path.substr(0, slash);
    const std::string base = slash == std::string::npos ? path : path.substr(slash + 1);
    std::string templ = parent + "/" + base + ".new-XXXXXX";
    std::vector<char> buf(templ.begin(), templ.end());
    buf.push_back('\0');
    if (!::mkdtemp(buf.data())) {
      if (errno == ENOENT)
        throw UsageError(parent +
                         " does not exist: the directory given for the work files (--checkpoint DIR, "
                         "--tmpdir DIR) must exist; tetstream makes " +
                         path + " inside it");
      throw IoError(path + ": cannot create the work directory: " + errno_text());
    }
    WorkDir made(buf.data());
    made.lock_or_refuse();
    write_marker(made.dir_, path);
    // RENAME_NOREPLACE: never onto a directory (even an empty one) that appeared
    // meanwhile; then the made one goes and PATH is judged as an existing path below.
    if (::renameat2(AT_FDCWD, made.dir_.c_str(), AT_FDCWD, path.c_str(), RENAME_NOREPLACE) == 0) {
      made.dir_ = path;
      return made;
    }
    const int err = errno;
    made.remove();
    if (err != EEXIST) throw IoError(path + ": cannot create the work directory: " + std::strerror(err));
    if (::lstat(path.c_str(), &st) != 0) throw IoError(path + ": cannot stat: " + errno_text());
  }
  if (S_ISLNK(st.st_mode)) throw UsageError(path + " is a symbolic link: tetstream does not follow it (remove it)");
  if (!S_ISDIR(st.st_mode)) throw UsageError(path + " exists and is not a directory");
  if (!is_own_work_dir(path))
    throw UsageError(path + " exists but was not made by tetstream (no " + kMarker +
                     " in it, or another user's): move it away or choose another directory");
  w.lock_or_refuse();
  return w;
}

void WorkDir::lock_or_refuse() {
  lock_fd_ = try_lock(dir_, /*create=*/true);
  if (lock_fd_ >= 0) return;
  if (errno == EWOULDBLOCK) throw UsageError(dir_ + " is in use: another tetstream process is running this job");
  throw IoError(dir_ + "/" + kLock + ": cannot lock: " + errno_text());
}

WorkDir::WorkDir(WorkDir&& other) noexcept : dir_(std::move(other.dir_)), lock_fd_(other.lock_fd_) {
  other.lock_fd_ = -1;
}

WorkDir::~WorkDir() {
  if (lock_fd_ >= 0) ::close(lock_fd_);
}

void WorkDir::remove_owned(bool keep_lock_and_marker) const {
  DIR* d = ::opendir(dir_.c_str());
  if (!d) return;
  std::vector<std::string> names;
  while (const dirent* e = ::readdir(d)) {
    const std::string name = e->d_name;
    const bool special = name == kLock || name == kMarker;
    if (special ? !keep_lock_and_marker : is_work_file_name(name)) names.push_back(name);
  }
  ::closedir(d);
  // The state first (without it the directory is no checkpoint, only stale work
  // files a later run removes), the marker last (until then the directory is
  // recognisably ours).
  const auto rank = [](const std::string& name) { return name == "state.json" ? 0 : name == kMarker ? 2 : 1; };
  std::stable_sort(names.begin(), names.end(),
                   [&](const std::string& a, const std::string& b) { return rank(a) < rank(b); });
  for (const std::string& name : names) {
    const std::string p = path(name);
    struct stat st {};
    // A directory under one of our names is not ours: never recurse.
    if (::lstat(p.c_str(), &st) == 0 && !S_ISDIR(st.st_mode)) ::unlink(p.c_str());
  }
}

void WorkDir::clear() const { remove_owned(/*keep_lock_and_marker=*/true); }

// Renames the directory to DIR.old-PID-N beside it (never onto anything: NOREPLACE),
// so that what is emptied next is no longer at DIR. False if it could not.
bool WorkDir::move_aside() noexcept {
  for (unsigned attempt = 0; attempt < 64; ++attempt) {
    const std::string aside = dir_ + ".old-" + std::to_string(::getpid()) + "-" + std::to_string(attempt);
    if (::renameat2(AT_FDCWD, dir_.c_str(), AT_FDCWD, aside.c_str(), RENAME_NOREPLACE) == 0) {
      dir_ = aside;
      return true;
    }
    if (errno != EEXIST) return false;
  }
  return false;
}

bool WorkDir::remove() noexcept {
  if (dir_.empty()) return true;
  // Out of the way first, then emptied: a process killed while removing its work
  // directory leaves DIR whole or gone, never half removed (an unmarked DIR that
  // --resume must refuse as not tetstream's, or a checkpoint naming files already
  // gone). What such a kill leaves is a marked DIR.old-PID-N without a state, which
  // the next run in that directory, or `tetstream clean`, removes. In place if the
  // rename fails (the removal itself then fails the same way).
  const std::string named = dir_;
  const bool aside = move_aside();
  remove_owned(/*keep_lock_and_marker=*/false);
  if (lock_fd_ >= 0) ::close(lock_fd_), lock_fd_ = -1;
  if (::rmdir(dir_.c_str()) == 0) return true;
  // Something not ours is left in it: back where the user put it.
  if (aside && ::renameat2(AT_FDCWD, dir_.c_str(), AT_FDCWD, named.c_str(), RENAME_NOREPLACE) == 0) dir_ = named;
  return false;
}

std::vector<StaleWorkDir> find_stale_work_dirs(const std::string& parent) {
  std::vector<StaleWorkDir> found;
  DIR* d = ::opendir(parent.empty() ? "." : parent.c_str());
  if (!d) throw IoError(parent + ": cannot list: " + errno_text());
  std::vector<std::string> candidates;
  while (const dirent* e = ::readdir(d)) {
    const std::string name = e->d_name;
    if (name != "." && name != "..") candidates.push_back((parent.empty() ? "." : parent) + "/" + name);
  }
  ::closedir(d);
  for (const std::string& path : candidates) {
    if (!is_own_work_dir(path)) continue;
    const int fd = try_lock(path, /*create=*/false);
    // No lock file: the process died between mkdtemp and its lock; the marker is
    // written after the lock, so a marked directory without one is not a live job's.
    if (fd < 0 && errno == EWOULDBLOCK) continue;
    if (fd >= 0) ::close(fd);
    struct stat st {};
    found.push_back({path, ::lstat((path + "/state.json").c_str(), &st) == 0});
  }
  return found;
}

namespace {
// The partial output a stale checkpoint's job kept for --resume (state.json names the
// output): removed with the checkpoint, which alone could finish it. Only a regular
// file of one link, this user's, that starts as a container or is still empty (the
// job's claim made it and was killed before writing) and that no process holds locked (a live job's claim
// holds its flock) is removed: an empty file holds nothing to lose.
void remove_orphaned_partial(const std::string& dir) {
  std::string output;
  try {
    std::ifstream in(dir + "/state.json", std::ios::binary);
    const nlohmann::json state = nlohmann::json::parse(in);
    output = state.at("job").at("output").get<std::string>();
  } catch (const std::exception&) {
    return;
  }
  if (output.empty()) return;
  const std::string partial = output + ".partial";
  const int fd = ::open(partial.c_str(), O_RDWR | O_NOFOLLOW | O_CLOEXEC);
  if (fd < 0) return;
  struct stat st {};
  unsigned char magic[8] = {};
  const bool ours = ::fstat(fd, &st) == 0 && S_ISREG(st.st_mode) && st.st_nlink == 1 && st.st_uid == ::geteuid() &&
                    (st.st_size == 0 || (::pread(fd, magic, sizeof magic, 0) == ssize_t(sizeof magic) &&
                                         std::memcmp(magic, io::kFileMagic.data(), sizeof magic) == 0)) &&
                    ::flock(fd, LOCK_EX | LOCK_NB) == 0;
  struct stat at {};
  if (ours && ::lstat(partial.c_str(), &at) == 0 && at.st_dev == st.st_dev && at.st_ino == st.st_ino)
    ::unlink(partial.c_str());
  ::close(fd);
}
}  // namespace

bool remove_stale_work_dir(const StaleWorkDir& stale) {
  try {
    WorkDir w = WorkDir::open_or_create(stale.path);  // refuses a link or a directory not ours, or a live job's
    if (stale.checkpoint) remove_orphaned_partial(w.dir());
    // A periodic job's checkpoint holds its padded job's, one level down (a work
    // directory of its own, stale with it): that one first, by the same rules.
    for (const StaleWorkDir& inner : find_stale_work_dirs(w.dir())) remove_stale_work_dir(inner);
    return w.remove();
  } catch (const Error&) {
    return false;
  }
}

}  // namespace tetstream::pipeline
