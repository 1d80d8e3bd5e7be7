#pragma once
// K ranks as K threads of one process, for tests of distributed code without MPI: a
// pipeline::Communicator over shared memory (every collective is a barrier, a copy and
// a barrier). run_ranks(K, f) calls f(comm) on K threads and waits for them.
#include "pipeline/util/communicator.hpp"

#include <barrier>
#include <cstring>
#include <exception>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace tetstream::test {

class ThreadRanks {
 public:
  explicit ThreadRanks(int k)
      : k_(k),
        barrier_(k),
        slots_(std::size_t(k)),
        matrix_(std::size_t(k)),
        send_(std::size_t(k)),
        counts_(std::size_t(k)) {}

  class Rank final : public pipeline::Communicator {
   public:
    Rank(ThreadRanks& all, int rank) : all_(all), rank_(rank) {}
    int rank() const override { return rank_; }
    int size() const override { return all_.k_; }
    int agree(int code) override {
      int most = 0;
      for (std::uint64_t c : all_gather(std::uint64_t(code))) most = std::max(most, int(c));
      return most;
    }
    std::vector<std::uint64_t> all_gather(std::uint64_t value) override {
      std::vector<std::uint64_t> out;
      for (const std::string& s : gather_all(std::string(reinterpret_cast<const char*>(&value), sizeof value))) {
        std::uint64_t v = 0;
        std::memcpy(&v, s.data(), sizeof v);
        out.push_back(v);
      }
      return out;
    }
    std::string broadcast(const std::string& bytes, int root) override { return gather_all(bytes)[std::size_t(root)]; }
    std::vector<std::string> gather(const std::string& bytes, int root) override {
      std::vector<std::string> all = gather_all(bytes);
      if (rank_ != root) all.clear();
      return all;
    }
    std::vector<std::uint64_t> all_to_all(const std::vector<std::uint64_t>& to_each) override {
      all_.matrix_[std::size_t(rank_)] = to_each;
      all_.barrier_.arrive_and_wait();
      std::vector<std::uint64_t> from(std::size_t(all_.k_));
      for (int r = 0; r < all_.k_; ++r) from[std::size_t(r)] = all_.matrix_[std::size_t(r)][std::size_t(rank_)];
      all_.barrier_.arrive_and_wait();
      return from;
    }
    void exchange(const void* send, const std::vector<std::uint64_t>& send_counts, void* receive,
                  const std::vector<std::uint64_t>& receive_counts, std::size_t record_bytes) override {
      all_.send_[std::size_t(rank_)] = static_cast<const char*>(send);
      all_.counts_[std::size_t(rank_)] = send_counts;
      all_.barrier_.arrive_and_wait();
      char* out = static_cast<char*>(receive);
      for (int r = 0; r < all_.k_; ++r) {
        std::uint64_t skip = 0;  // what rank r sends the ranks before this one
        for (int q = 0; q < rank_; ++q) skip += all_.counts_[std::size_t(r)][std::size_t(q)];
        const std::uint64_t n = receive_counts[std::size_t(r)];
        if (n) std::memcpy(out, all_.send_[std::size_t(r)] + skip * record_bytes, n * record_bytes);
        out += n * record_bytes;
      }
      all_.barrier_.arrive_and_wait();
    }
    std::uint64_t bytes_sent() const override { return 0; }

   private:
    std::vector<std::string> gather_all(const std::string& bytes) {
      all_.slots_[std::size_t(rank_)] = bytes;
      all_.barrier_.arrive_and_wait();
      std::vector<std::string> out = all_.slots_;
      all_.barrier_.arrive_and_wait();
      return out;
    }
    ThreadRanks& all_;
    int rank_;
  };

 private:
  template <class F>
  friend void run_ranks(int k, F&& f);
  int k_;
  std::barrier<> barrier_;
  std::vector<std::string> slots_;
  std::vector<std::vector<std::uint64_t>> matrix_;
  std::vector<const char*> send_;
  std::vector<std::vector<std::uint64_t>> counts_;
};

// f(comm) on k threads, one rank each; the first exception (by rank) is rethrown.
template <class F>
void run_ranks(int k, F&& f) {
  ThreadRanks all(k);
  std::vector<std::exception_ptr> errors(static_cast<std::size_t>(k));
  std::vector<std::thread> threads;
  for (int r = 0; r < k; ++r)
    threads.emplace_back([&, r] {
      ThreadRanks::Rank comm(all, r);
      try {
        f(comm);
      } catch (...) {
        errors[std::size_t(r)] = std::current_exception();
      }
    });
  for (auto& t : threads) t.join();
  for (auto& e : errors)
    if (e) std::rethrow_exception(e);
}

}  // namespace tetstream::test
