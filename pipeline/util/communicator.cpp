#include "pipeline/util/communicator.hpp"

#include <cstdlib>
#include <cstring>

namespace tetstream::pipeline {

namespace {

class SingleProcess final : public Communicator {
 public:
  int rank() const override { return 0; }
  int size() const override { return 1; }
  int agree(int code) override { return code; }
  std::vector<std::uint64_t> all_gather(std::uint64_t value) override { return {value}; }
  std::string broadcast(const std::string& bytes, int) override { return bytes; }
  std::vector<std::string> gather(const std::string& bytes, int) override { return {bytes}; }
  std::vector<std::uint64_t> all_to_all(const std::vector<std::uint64_t>& to_each) override { return to_each; }
  void exchange(const void* send, const std::vector<std::uint64_t>& send_counts, void* receive,
                const std::vector<std::uint64_t>&, std::size_t record_bytes) override {
    if (send_counts.at(0) != 0) std::memcpy(receive, send, send_counts[0] * record_bytes);
  }
  std::uint64_t bytes_sent() const override { return 0; }
};

}  // namespace

Communicator& single_process() {
  static SingleProcess one;
  return one;
}

int launcher_size() {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_SIZE", "MPI_LOCALNRANKS"}) {
    if (const char* v = std::getenv(name); v && *v) {
      const int n = std::atoi(v);
      if (n > 0) return n;
    }
  }
  return 1;
}

}  // namespace tetstream::pipeline
