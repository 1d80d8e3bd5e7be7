#include "pipeline/progress.hpp"

#include <spdlog/spdlog.h>

#include <cmath>
#include <cstdio>
#include <sys/ioctl.h>
#include <unistd.h>

namespace tetstream::pipeline {

namespace {
using Clock = std::chrono::steady_clock;
constexpr std::int64_t kTtyIntervalNs = 200'000'000;       // redraw 5 times a second
constexpr std::int64_t kLogIntervalNs = 10'000'000'000LL;  // one log line every 10 s
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
  if (s < 60) std::snprintf(buf, sizeof buf, "%.1fs", s);
  else if (s < 3600) std::snprintf(buf, sizeof buf, "%dm%02ds", int(s) / 60, int(s) % 60);
  else std::snprintf(buf, sizeof buf, "%dh%02dm", int(s) / 3600, (int(s) % 3600) / 60);
  return buf;
}

Progress::Progress(std::string what, std::string unit, std::uint64_t total, bool enabled)
    : what_(std::move(what)), unit_(std::move(unit)), total_(total), enabled_(enabled),
      tty_(isatty(STDERR_FILENO) != 0), start_(Clock::now()) {
  next_report_ns_ = tty_ ? kTtyIntervalNs : kLogIntervalNs;
}

Progress::~Progress() { finish(); }

double Progress::seconds() const {
  return std::chrono::duration<double>(Clock::now() - start_).count();
}

void Progress::add(std::uint64_t n) {
  done_.fetch_add(n, std::memory_order_relaxed);
  if (!enabled_) return;
  const std::int64_t now =
      std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - start_).count();
  std::int64_t due = next_report_ns_.load(std::memory_order_relaxed);
  if (now < due) return;
  const std::int64_t step = tty_ ? kTtyIntervalNs : kLogIntervalNs;
  if (!next_report_ns_.compare_exchange_strong(due, now + step)) return;  // another thread prints
  report(false);
}

void Progress::report(bool final) {
  std::lock_guard lock(print_mutex_);
  const double t = seconds();
  const double done = double(done_.load(std::memory_order_relaxed));
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
  if (enabled_) report(true);
}

}  // namespace tetstream::pipeline
