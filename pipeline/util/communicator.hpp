#pragma once
// The processes of one job: a single process (the default), or the ranks of a job
// started by `mpirun -n K tetstream run ...` (pipeline/run_distributed.hpp). The
// collective calls here are all a distributed job needs; every rank calls each of
// them in the same order. MPI itself is confined to communicator_mpi.cpp, built when
// the build found it (-DTETSTREAM_MPI): the rest of the code sees only this class.
//
// Failures: a rank that fails keeps its exception and tells the others at the end of
// the step (together(), below); every rank then stops, the failing one with its error
// line, the others with PeerFailed (no line of their own, the same exit code), so one
// error line and one exit code come out of the job, as from a single process.
#include "core/error.hpp"

#include <cstdint>
#include <algorithm>
#include <exception>
#include <memory>
#include <string>
#include <vector>

namespace tetstream::pipeline {

// Another rank of this job failed and said why: this one stops with the same exit code
// and no message of its own.
class PeerFailed : public Error {
 public:
  explicit PeerFailed(ExitCode code) : Error(code, "another rank of the job failed") {}
};

class Communicator {
 public:
  virtual ~Communicator() = default;
  virtual int rank() const = 0;
  virtual int size() const = 0;
  // The exit code every rank reached (the largest; 0: every rank went well): how
  // ranks decide together to go on or stop.
  virtual int agree(int code) = 0;
  // Every rank's value, by rank.
  virtual std::vector<std::uint64_t> all_gather(std::uint64_t value) = 0;
  // `root`'s bytes, on every rank.
  virtual std::string broadcast(const std::string& bytes, int root) = 0;
  // Every rank's bytes, by rank, on `root` (empty elsewhere).
  virtual std::vector<std::string> gather(const std::string& bytes, int root) = 0;
  // `to_each[r]` to rank r, from every rank: what each rank sent this one, by rank.
  virtual std::vector<std::uint64_t> all_to_all(const std::vector<std::uint64_t>& to_each) = 0;
  // Records of `record_bytes` each, from every rank to every rank (the sort's exchange):
  // `send` holds send_counts[0] records for rank 0, then send_counts[1] for rank 1, ...;
  // `receive` gets receive_counts[0] from rank 0, then rank 1's, ... (the counts an
  // all_to_all of the send counts returned). A call's counts and their sums stay below
  // 2^31 records (the caller's rounds keep them so; std::length_error otherwise).
  virtual void exchange(const void* send, const std::vector<std::uint64_t>& send_counts, void* receive,
                        const std::vector<std::uint64_t>& receive_counts, std::size_t record_bytes) = 0;
  // The bytes this rank has handed to the calls above as a sender (counts, codes,
  // payloads; a broadcast's payload counted once, at its root): what a job's ranks
  // tell each other, as opposed to what they share through files.
  virtual std::uint64_t bytes_sent() const = 0;
};

// One process of its own: rank 0 of 1.
Communicator& single_process();
// How many processes an MPI launcher started, from its environment (OpenMPI, MPICH,
// PMIx); 1 when none did.
int launcher_size();

// Runs `work` on this rank, then learns how every rank's went: when any failed, the
// lowest failing rank rethrows its error here and every other rank throws PeerFailed
// with that rank's exit code, so the job prints one error line (several ranks failing
// alike, on bad options, say, would print it several times) and exits with one code.
template <class F>
void together(Communicator& comm, F&& work) {
  std::uint64_t code = 0;
  std::exception_ptr failure;
  try {
    work();
  } catch (const PeerFailed& e) {
    code = std::uint64_t(e.code());
    failure = std::current_exception();
  } catch (const Error& e) {
    code = std::uint64_t(e.code());
    failure = std::current_exception();
  } catch (...) {
    code = std::uint64_t(ExitCode::kIoFailure);
    failure = std::current_exception();
  }
  const std::vector<std::uint64_t> codes = comm.all_gather(code);
  for (std::size_t r = 0; r < codes.size(); ++r) {
    if (codes[r] == 0) continue;
    if (int(r) == comm.rank()) std::rethrow_exception(failure);
    throw PeerFailed(ExitCode(int(codes[r])));
  }
}

// Every rank's records for this one, by rank in order: `to[r]` goes to rank r (every
// rank calls it, with to.size() == comm.size()). In rounds of fewer than 2^30 records
// a call, as exchange() asks; T is copied as bytes.
template <class T>
std::vector<T> exchange_records(Communicator& comm, const std::vector<std::vector<T>>& to) {
  const std::size_t k = std::size_t(comm.size());
  std::vector<std::uint64_t> counts(k);
  std::uint64_t most = 0;
  for (std::size_t r = 0; r < k; ++r) most = std::max<std::uint64_t>(most, counts[r] = to[r].size());
  const std::vector<std::uint64_t> incoming = comm.all_to_all(counts);
  for (std::uint64_t n : incoming) most = std::max(most, n);
  std::uint64_t rounds_needed = 0;
  const std::uint64_t piece = std::max<std::uint64_t>(1, (std::uint64_t(1) << 30) / k);
  for (std::uint64_t r : comm.all_gather((most + piece - 1) / piece)) rounds_needed = std::max(rounds_needed, r);
  std::vector<std::uint64_t> at(k + 1, 0);  // where each sender's records start in the result
  for (std::size_t r = 0; r < k; ++r) at[r + 1] = at[r] + incoming[r];
  std::vector<T> out(std::size_t(at[k]));
  std::vector<T> send;
  std::vector<T> receive;
  for (std::uint64_t round = 0; round < rounds_needed; ++round) {
    std::vector<std::uint64_t> sc(k), rc(k);
    send.clear();
    for (std::size_t r = 0; r < k; ++r) {
      const std::uint64_t from = std::min(counts[r], round * piece), to_end = std::min(counts[r], from + piece);
      sc[r] = to_end - from;
      send.insert(send.end(), to[r].begin() + std::ptrdiff_t(from), to[r].begin() + std::ptrdiff_t(to_end));
      const std::uint64_t rf = std::min(incoming[r], round * piece);
      rc[r] = std::min(incoming[r], rf + piece) - rf;
    }
    std::uint64_t total = 0;
    for (std::uint64_t n : rc) total += n;
    receive.resize(std::size_t(total));
    comm.exchange(send.data(), sc, receive.data(), rc, sizeof(T));
    std::uint64_t got = 0;
    for (std::size_t r = 0; r < k; ++r) {
      const std::uint64_t rf = std::min(incoming[r], round * piece);
      std::copy_n(receive.begin() + std::ptrdiff_t(got), rc[r], out.begin() + std::ptrdiff_t(at[r] + rf));
      got += rc[r];
    }
  }
  return out;
}

}  // namespace tetstream::pipeline
