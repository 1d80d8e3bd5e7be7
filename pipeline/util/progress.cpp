#include "pipeline/util/progress.hpp"

#include "core/error.hpp"
#include "io/output_file.hpp"

#include <spdlog/spdlog.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fcntl.h>
#include <sys/ioctl.h>
#include <unistd.h>

namespace tetstream::pipeline {

namespace {
using Clock = std::chrono::steady_clock;
constexpr std::int64_t kTtyIntervalNs = 200'000'000;       // redraw 5 times a second
constexpr std::int64_t kLogIntervalNs = 10'000'000'000LL;  // one log line every 10 s
constexpr std::int64_t kShareIntervalNs = 1'000'000'000;   // a rank's shared count, once a second
// Columns of the terminal on stderr; 0 when it says none.
std::size_t terminal_columns() {
  struct winsize w {};
  return ::ioctl(STDERR_FILENO, TIOCGWINSZ, &w) == 0 ? w.ws_col : 0;
}
}  // namespace

std::string human_count(double n) {
  const char* suffix[] = {"", " k", " M", " G", " T"};
  int i = 0;
  while (std::fabs(n) >= 1000.0 && i < 4) n /= 1000.0, ++i;
  char buf[32];
  std::snprintf(buf, sizeof buf, i == 0 ? "%.0f%s" : "%.2f%s", n, suffix[i]);
  return buf;
}

std::string human_bytes(double bytes) {
  const char* suffix[] = {"B", "KiB", "MiB", "GiB", "TiB"};
  int i = 0;
  while (bytes >= 1024.0 && i < 4) bytes /= 1024.0, ++i;
  char buf[32];
  std::snprintf(buf, sizeof buf, i == 0 ? "%.0f %s" : "%.1f %s", bytes, suffix[i]);
  return buf;
}

std::string human_duration(double s) {
  char buf[32];
  if (!std::isfinite(s) || s < 0) return "?";
  if (s < 60)
    std::snprintf(buf, sizeof buf, "%.1fs", s);
  else if (s < 3600)
    std::snprintf(buf, sizeof buf, "%dm%02ds", int(s) / 60, int(s) % 60);
  else
    std::snprintf(buf, sizeof buf, "%dh%02dm", int(s) / 3600, (int(s) % 3600) / 60);
  return buf;
}

Progress::Progress(std::string what, std::string unit, std::uint64_t total, bool enabled)
    : what_(std::move(what)),
      unit_(std::move(unit)),
      total_(total),
      enabled_(enabled),
      tty_(isatty(STDERR_FILENO) != 0),
      start_(Clock::now()) {
  next_report_ns_ = tty_ ? kTtyIntervalNs : kLogIntervalNs;
}

Progress::~Progress() {
  finish();
  if (share_fd_ >= 0) ::close(share_fd_);
}

void Progress::share_to(const std::string& path, std::uint64_t base) {
  // A file of the job's own work directory, never through a link.
  try {
    share_fd_ = io::create_work_file(path);
  } catch (const IoError& e) {
    spdlog::debug("cannot share progress: {}", e.what());
    return;
  }
  share_path_ = path;
  share_base_ = base;
  share(false);
}

void Progress::add_shared(std::vector<std::string> paths) { peers_ = std::move(paths); }

std::uint64_t Progress::counted() {
  return done_.load(std::memory_order_relaxed) + (peers_.empty() ? 0 : peers_done());
}

std::uint64_t Progress::done_with_shared() {
  std::lock_guard lock(print_mutex_);
  return counted();
}

// Progress is advice: a write that fails is dropped, never an error of the job.
void Progress::share(bool final) {
  const std::uint64_t done = done_.load(std::memory_order_relaxed);
  const std::uint64_t n = done > share_base_ ? done - share_base_ : 0;
  if (::pwrite(share_fd_, &n, sizeof n, 0) != ssize_t(sizeof n) && final)
    spdlog::debug("{}: cannot share progress: {}", share_path_, std::strerror(errno));
}

std::uint64_t Progress::peers_done() {
  const std::int64_t now = std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - start_).count();
  if (peers_read_ns_ >= 0 && now - peers_read_ns_ < kShareIntervalNs) return peers_done_;
  peers_read_ns_ = now;
  std::uint64_t sum = 0;
  for (const std::string& p : peers_) {
    const int fd = ::open(p.c_str(), O_RDONLY | O_NOFOLLOW | O_CLOEXEC);
    if (fd < 0) continue;  // that rank has not started yet
    std::uint64_t n = 0;
    if (::pread(fd, &n, sizeof n, 0) == ssize_t(sizeof n)) sum += n;
    ::close(fd);
  }
  return peers_done_ = sum;
}

double Progress::seconds() const { return std::chrono::duration<double>(Clock::now() - start_).count(); }

void Progress::add(std::uint64_t n) {
  done_.fetch_add(n, std::memory_order_relaxed);
  if (!enabled_ && share_fd_ < 0) return;  // silent and not shared: nothing to time
  const std::int64_t now = std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - start_).count();
  if (share_fd_ >= 0) {
    std::int64_t due_share = next_share_ns_.load(std::memory_order_relaxed);
    if (now >= due_share && next_share_ns_.compare_exchange_strong(due_share, now + kShareIntervalNs)) share(false);
  }
  if (!enabled_) return;
  std::int64_t due = next_report_ns_.load(std::memory_order_relaxed);
  if (now < due) return;
  const std::int64_t step = tty_ ? kTtyIntervalNs : kLogIntervalNs;
  if (!next_report_ns_.compare_exchange_strong(due, now + step)) return;  // another thread prints
  report(false);
}

void Progress::report(bool final) {
  std::lock_guard lock(print_mutex_);
  const double t = seconds();
  const double done = double(counted());
  const double rate = t > 0 ? done / t : 0.0;
  std::string line = what_ + ": " + human_count(done);
  if (total_ > 0) {
    char pct[16];
    std::snprintf(pct, sizeof pct, " (%.1f%%)", 100.0 * done / double(total_));
    line += " / " + human_count(double(total_)) + " " + unit_ + pct;
  } else {
    line += " " + unit_;
  }
  line += ", " + human_count(rate) + " " + unit_ + "/s";
  if (final) {
    line += ", " + human_duration(t);
  } else if (total_ > 0 && rate > 0) {
    line += ", ETA " + human_duration((double(total_) - done) / rate);
  }
  if (tty_ && !final) {
    // One row: a line as wide as the terminal would wrap, and \r\033[K clears only the
    // last row, leaving a trail of the others.
    const std::size_t columns = terminal_columns();
    if (columns > 1 && line.size() > columns - 1) line.resize(columns - 1);
    std::fprintf(stderr, "\r\033[K%s", line.c_str());
    std::fflush(stderr);
  } else {
    if (tty_) std::fprintf(stderr, "\r\033[K");
    spdlog::info("{}", line);
  }
}

void Progress::finish() {
  if (finished_) return;
  finished_ = true;
  if (share_fd_ >= 0) share(true);
  if (enabled_) report(true);
}

}  // namespace tetstream::pipeline
