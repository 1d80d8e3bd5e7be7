#pragma once
// Progress of long work: a single rewritten line with rate and ETA when stderr is a
// terminal, a log line every few seconds otherwise (CI logs, `nohup`, pipes).
// Thread-safe: workers call add() from any thread; only one thread prints at a time.
#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>
#include <vector>

namespace tetstream::pipeline {

class Progress {
 public:
  // `what` names the work ("generating", "sorting"); `unit` the counted things
  // ("points"); `total` may be 0 when unknown (no ETA then). `enabled` false
  // silences it (-q).
  Progress(std::string what, std::string unit, std::uint64_t total, bool enabled = true);
  ~Progress();

  void add(std::uint64_t n);

  // ---- one line for the ranks of a job (pipeline/run_distributed.cpp) ----
  // Each rank's count goes through a small file of the job's work directory (8 bytes,
  // written at most once a second and at finish, whether this Progress prints or not):
  // ranks need no message while their threads work. `base` is subtracted: the count
  // shared is the work since `base` (a rank's first label).
  void share_to(const std::string& path, std::uint64_t base);
  // Adds the counts those files hold (read at most once a second) to this one's in
  // every line it prints: rank 0's line then counts the whole job (its total the job's).
  void add_shared(std::vector<std::string> paths);
  // This one's count and the shared ones' (as last read), as a line shows it.
  std::uint64_t done_with_shared();
  // Ends the line on a terminal and logs the final count and rate once.
  void finish();
  double seconds() const;
  std::uint64_t done() const { return done_.load(std::memory_order_relaxed); }

 private:
  void report(bool final);
  void share(bool final);
  std::uint64_t peers_done();  // under print_mutex_
  std::uint64_t counted();     // under print_mutex_

  std::string what_, unit_;
  std::uint64_t total_;
  bool enabled_, tty_;
  bool finished_ = false;
  std::atomic<std::uint64_t> done_{0};
  std::atomic<std::int64_t> next_report_ns_{0};
  std::chrono::steady_clock::time_point start_;
  std::mutex print_mutex_;
  // Sharing (share_to, add_shared).
  int share_fd_ = -1;
  std::string share_path_;
  std::uint64_t share_base_ = 0;
  std::atomic<std::int64_t> next_share_ns_{0};
  std::vector<std::string> peers_;
  std::uint64_t peers_done_ = 0;  // as last read (under print_mutex_)
  std::int64_t peers_read_ns_ = -1;
};

// "1.23 M" style number for human output.
std::string human_count(double n);
// "12.3 MiB" style size for human output.
std::string human_bytes(double bytes);
// "1h02m", "3m20s", "12.4s".
std::string human_duration(double seconds);

}  // namespace tetstream::pipeline
