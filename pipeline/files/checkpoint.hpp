#pragma once
// The checkpoint of a resumable `run` (docs/architecture.md, "Checkpoints").
//
// A checkpoint is a directory holding the job's working files (the sort's runs and
// their hull candidates, the sorted point file, the tets of the frame being filled)
// and `state.json`, which says how far the job got and names the files that carry
// its progress. Invariants, which make a crash at any instant harmless:
//   - state.json is only ever replaced atomically: written to state.json.tmp,
//     fsynced, renamed over the old one, and the directory fsynced;
//   - a file is complete and fsynced before any state.json names it;
//   - a file that the current state.json names is never modified or removed (a new
//     step writes new files; the old ones go after the state that named them).
// So the directory always describes one consistent moment of the job, and a resumed
// job continues from it. state.json carries a CRC32C of its own body: a damaged or
// hand-edited state is refused, not trusted.
//
// The job's identity: a fingerprint of the input (size, modification time, and a
// CRC32C over samples spread through the file) and the options that change the
// output. A resumed job with a different input or options is refused.
#include "core/error.hpp"
#include "pipeline/files/work_dir.hpp"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <optional>
#include <string>

namespace tetstream::pipeline {

// A checkpoint that cannot be trusted (exit code of bad input): the job refuses it
// and says how to start over; the directory is left for the user to inspect.
class DamagedCheckpoint : public InputError {
 public:
  explicit DamagedCheckpoint(const std::string& message) : InputError(message) {}
};

// Size, modification time and a sampled CRC32C of a file: cheap (64 reads of 4 KiB)
// and enough to notice a replaced, regenerated, truncated or appended file.
nlohmann::json fingerprint_file(const std::string& path);

class Checkpoint {
 public:
  // 2: every file the state names carries its CRC32C; the directory has a marker.
  // 3: runs in the container's point records (28 or 16 bytes, not 32), the sorted
  //    points in the partial output's points section, runs consumed by the merge.
  static constexpr int kVersion = 3;

  explicit Checkpoint(std::string dir) : dir_(std::move(dir)) {}
  // A rank's part of a job's checkpoint under MPI (pipeline/run_distributed.hpp): its
  // state in `state_name` ("rank-R.json"), beside rank 0's state.json in the directory
  // that rank 0 made and holds locked. It joins that directory (join(), not
  // create_and_lock()); its files are removed with rank 0's (clear(), remove()).
  Checkpoint(std::string dir, std::string state_name) : dir_(std::move(dir)), state_name_(std::move(state_name)) {}
  Checkpoint(const Checkpoint&) = delete;
  Checkpoint& operator=(const Checkpoint&) = delete;

  const std::string& dir() const { return dir_; }
  std::string path(const std::string& name) const { return dir_ + "/" + name; }
  bool exists() const;  // the directory holds this checkpoint's state file

  // Makes the directory if needed (its parent must exist; IoError otherwise), or
  // reopens one that tetstream made (a WorkDir: never a link, another user's or a
  // directory without the marker: UsageError), and takes its lock (released by the
  // kernel if the process dies): UsageError when another process holds it, i.e. runs
  // the same job right now.
  void create_and_lock();
  // A rank's checkpoint: checks that the directory is one tetstream made (not a link,
  // the marker in it): IoError otherwise. Takes no lock (rank 0 holds it).
  void join() const;
  // The saved state (without its CRC). Throws InputError naming the file when it is
  // damaged: unreadable JSON, a CRC mismatch, another format or version.
  nlohmann::json load() const;
  // Replaces the state atomically (see above). Throws IoError.
  void save(nlohmann::json state);
  // Removes the job's files but the lock and the marker: --force starting over.
  void clear() const;
  // Removes the job's files and, when nothing else is in it, the directory (ignores
  // errors: used on the way out; a directory left with other files in it is logged).
  void remove();

 private:
  std::string dir_;
  std::string state_name_ = "state.json";
  std::optional<WorkDir> work_;  // set by create_and_lock
};

// Writes `bytes` bytes to DIR/NAME through NAME.tmp, fsync and rename, so the file is
// complete whenever it exists. Throws IoError.
void write_file_atomically(const std::string& dir, const std::string& name, const void* data, std::size_t bytes);
// Reads a whole file written by write_file_atomically: DamagedCheckpoint when it is
// missing, not `bytes` long or its bytes do not have the CRC32C `crc`.
void read_file_exactly(const std::string& path, void* data, std::size_t bytes, std::uint32_t crc);
// Whether PATH holds exactly `bytes` bytes with the CRC32C `crc` (read in full): how a
// resumed job decides to trust a file that its checkpoint names.
bool file_matches(const std::string& path, std::uint64_t bytes, std::uint32_t crc);
// Whether bytes [offset, offset + bytes) of PATH are all there with the CRC32C `crc`
// (the points section inside a partial output).
bool region_matches(const std::string& path, std::uint64_t offset, std::uint64_t bytes, std::uint32_t crc);

}  // namespace tetstream::pipeline
