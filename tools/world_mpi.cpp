// The communicator of a job started by an MPI launcher: MPI_COMM_WORLD. Only the main
// thread calls MPI (MPI_THREAD_FUNNELED); the stages' OpenMP threads never do.
#include "tools/world.hpp"

#include <mpi.h>

#include <algorithm>
#include <cstdint>
#include <stdexcept>
#include <optional>
#include <string>

namespace tetstream::cli {

using pipeline::Communicator;
using pipeline::launcher_size;
using pipeline::single_process;

namespace {

void check(int rc, const char* what) {
  if (rc != MPI_SUCCESS) {
    char text[MPI_MAX_ERROR_STRING];
    int n = 0;
    MPI_Error_string(rc, text, &n);
    throw IoError(std::string("MPI: ") + what + ": " + std::string(text, std::size_t(n)));
  }
}

class MpiWorld final : public Communicator {
 public:
  MpiWorld() {
    check(MPI_Comm_rank(MPI_COMM_WORLD, &rank_), "rank");
    check(MPI_Comm_size(MPI_COMM_WORLD, &size_), "size");
  }
  int rank() const override { return rank_; }
  int size() const override { return size_; }
  int agree(int code) override {
    int all = 0;
    sent_ += sizeof code;
    check(MPI_Allreduce(&code, &all, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD), "agree");
    return all;
  }
  std::vector<std::uint64_t> all_gather(std::uint64_t value) override {
    std::vector<std::uint64_t> all(static_cast<std::size_t>(size_));
    sent_ += sizeof value;
    check(MPI_Allgather(&value, 1, MPI_UINT64_T, all.data(), 1, MPI_UINT64_T, MPI_COMM_WORLD), "all_gather");
    return all;
  }
  std::string broadcast(const std::string& bytes, int root) override {
    std::uint64_t n = bytes.size();
    check(MPI_Bcast(&n, 1, MPI_UINT64_T, root, MPI_COMM_WORLD), "broadcast");
    std::string out = rank_ == root ? bytes : std::string(std::size_t(n), '\0');
    if (rank_ == root) sent_ += sizeof n + n;
    // Bytes beyond 2^31 in pieces (MPI counts are int).
    for (std::uint64_t at = 0; at < n;) {
      const int piece = int(std::min<std::uint64_t>(n - at, std::uint64_t(1) << 30));
      check(MPI_Bcast(out.data() + at, piece, MPI_BYTE, root, MPI_COMM_WORLD), "broadcast");
      at += std::uint64_t(piece);
    }
    return out;
  }
  std::vector<std::string> gather(const std::string& bytes, int root) override {
    // Small messages (summaries, paths, a rank's placed frames: 40 bytes a frame):
    // one count, then one Gatherv.
    const int n = int(bytes.size());
    sent_ += sizeof n + bytes.size();
    std::vector<int> counts(static_cast<std::size_t>(size_)), displs(static_cast<std::size_t>(size_));
    check(MPI_Gather(&n, 1, MPI_INT, counts.data(), 1, MPI_INT, root, MPI_COMM_WORLD), "gather");
    std::string all;
    if (rank_ == root) {
      int total = 0;
      for (int r = 0; r < size_; ++r) displs[std::size_t(r)] = total, total += counts[std::size_t(r)];
      all.resize(std::size_t(total));
    }
    check(MPI_Gatherv(bytes.data(), n, MPI_BYTE, all.data(), counts.data(), displs.data(), MPI_BYTE, root,
                      MPI_COMM_WORLD),
          "gather");
    std::vector<std::string> out;
    if (rank_ == root)
      for (int r = 0; r < size_; ++r)
        out.push_back(all.substr(std::size_t(displs[std::size_t(r)]), std::size_t(counts[std::size_t(r)])));
    return out;
  }
  std::vector<std::uint64_t> all_to_all(const std::vector<std::uint64_t>& to_each) override {
    std::vector<std::uint64_t> from_each(static_cast<std::size_t>(size_));
    sent_ += to_each.size() * sizeof(std::uint64_t);
    check(MPI_Alltoall(to_each.data(), 1, MPI_UINT64_T, from_each.data(), 1, MPI_UINT64_T, MPI_COMM_WORLD),
          "all_to_all");
    return from_each;
  }
  void exchange(const void* send, const std::vector<std::uint64_t>& send_counts, void* receive,
                const std::vector<std::uint64_t>& receive_counts, std::size_t record_bytes) override {
    // Counts in records of a contiguous type, so that a round's displacements (ints)
    // count records, not bytes.
    auto as_ints = [](const std::vector<std::uint64_t>& counts, std::vector<int>& n, std::vector<int>& displs) {
      std::uint64_t total = 0;
      for (std::size_t r = 0; r < counts.size(); ++r) {
        if (counts[r] > std::uint64_t(INT32_MAX) || total > std::uint64_t(INT32_MAX) - counts[r])
          throw std::length_error("exchange: a round of more than 2^31 records");
        n[r] = int(counts[r]), displs[r] = int(total);
        total += counts[r];
      }
      return total;
    };
    const std::size_t k = static_cast<std::size_t>(size_);
    std::vector<int> sn(k), sd(k), rn(k), rd(k);
    // What leaves this rank: its records for the others.
    sent_ += (as_ints(send_counts, sn, sd) - send_counts[std::size_t(rank_)]) * record_bytes;
    as_ints(receive_counts, rn, rd);
    MPI_Datatype record;
    check(MPI_Type_contiguous(int(record_bytes), MPI_BYTE, &record), "exchange");
    check(MPI_Type_commit(&record), "exchange");
    const int rc =
        MPI_Alltoallv(send, sn.data(), sd.data(), record, receive, rn.data(), rd.data(), record, MPI_COMM_WORLD);
    MPI_Type_free(&record);
    check(rc, "exchange");
  }
  std::uint64_t bytes_sent() const override { return sent_; }

 private:
  int rank_ = 0, size_ = 1;
  std::uint64_t sent_ = 0;
};

std::optional<MpiWorld>& the_world() {
  static std::optional<MpiWorld> w;
  return w;
}

}  // namespace

bool mpi_built() { return true; }

Communicator& world() {
  if (the_world()) return *the_world();
  return single_process();
}

WorldSession::WorldSession(int& argc, char**& argv) {
  // Only under a launcher: a plain `tetstream` stays the single-process tool (MPI's
  // singleton start would look for a runtime it does not need).
  if (launcher_size() <= 1) return;
  int provided = 0;
  check(MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided), "init");
  // Errors come back as codes (check() turns them into IoError), not as an abort.
  MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
  the_world().emplace();
}

WorldSession::~WorldSession() {
  if (the_world()) {
    the_world().reset();
    MPI_Finalize();
  }
}

}  // namespace tetstream::cli
