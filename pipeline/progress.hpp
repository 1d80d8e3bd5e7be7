#pragma once
// Progress of long work: a single rewritten line with rate and ETA when stderr is a
// terminal, a log line every few seconds otherwise (CI logs, `nohup`, pipes).
// Thread-safe: workers call add() from any thread; only one thread prints at a time.
#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

namespace tetstream::pipeline {

class Progress {
 public:
  // `what` names the work ("generating", "sorting"); `unit` the counted things
  // ("points"); `total` may be 0 when unknown (no ETA then). `enabled` false
  // silences it (-q).
  Progress(std::string what, std::string unit, std::uint64_t total, bool enabled = true);
  ~Progress();

  void add(std::uint64_t n);
  // Ends the line on a terminal and logs the final count and rate once.
  void finish();
  double seconds() const;
  std::uint64_t done() const { return done_.load(std::memory_order_relaxed); }

 private:
  void report(bool final);

  std::string what_, unit_;
  std::uint64_t total_;
  bool enabled_, tty_;
  bool finished_ = false;
  std::atomic<std::uint64_t> done_{0};
  std::atomic<std::int64_t> next_report_ns_{0};
  std::chrono::steady_clock::time_point start_;
  std::mutex print_mutex_;
};

// "1.23 M" style number for human output.
std::string human_count(double n);
// "12.3 MiB" style size for human output.
std::string human_bytes(double bytes);
// "1h02m", "3m20s", "12.4s".
std::string human_duration(double seconds);

}  // namespace tetstream::pipeline
