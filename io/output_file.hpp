#pragma once
// A buffered output file that never leaves a partial result looking complete: bytes go
// to "PATH.partial", commit() flushes, syncs and renames it to PATH, and an OutputFile
// destroyed without commit() removes the partial file. Used by the container writer
// and the mesh converters. Not thread-safe: one writer thread.
//
// A resumable job sets keep_on_failure(true): then the destructor without commit()
// only closes the file, and PATH.partial stays for a later reopen(). It does not flush
// the buffer first (a failed job may have a full disk; a destructor must not throw):
// what was written after the last flush()/sync() may be missing or torn, which is why
// a resumed writer cuts the file back to a checkpoint it synced.
#include <cstddef>
#include <fcntl.h>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <utility>

namespace tetstream::io {

// Refuses (UsageError) an output path the tool must not write: a directory, a device,
// pipe or socket, or a symbolic link (the final rename would replace the link, or
// the device node as root). A missing path or a regular file is fine.
void check_output_path(const std::string& path);
// Refuses (UsageError) writing `output` when it, or OUTPUT.partial, is `input` (the
// same file by device and inode, whatever the spelling or hard link).
void refuse_input_as_output(const std::string& input, const std::string& output);

// The files this process reads and the outputs it has finished, by (st_dev, st_ino):
// an output is never one of them. Readers note each input as they open it (the
// container, point and npy readers do; a command notes the others), and every output
// (OutputClaim) is refused when its path or its partial file is one of these files,
// whatever its spelling or hard link. Missing paths and non-regular files are not noted.
void note_input(const std::string& path);
void note_input_fd(int fd);
// Forgets them: a process that runs several commands (the Python package) starts each
// with none, so that an inode the filesystem reuses is never taken for an input.
void forget_noted_files();
// Whether files are noted at all. A command is one process's work in the tool (the
// binary's main turns this on, and so does the Python package, which forgets the notes
// at each command); a program linking the libraries runs many operations over the same
// files in one process and has no such unit, so nothing is noted by default there (the
// other checks of an output, links, non-regular files, the input itself, still hold).
void note_files(bool on);
// Whether `path` names a file this process has read or written (by device and inode).
bool is_noted_input(const std::string& path);
// Refuses (UsageError) standard output redirected into a file this process reads
// (`cat c.tets >> c.tets` would read what it appends).
void refuse_stdout_into_input();

// Creates a work file in a directory the job made (a sort run, a checkpoint's
// temporary file, a scratch file, a spill): a name already there is unlinked first (a
// planted link or hard link goes, its target untouched), then the file is made with
// O_CREAT | O_EXCL | O_NOFOLLOW, so nothing but a new file of this process is ever
// written. `flags`: O_WRONLY or O_RDWR. Returns the descriptor; IoError when it cannot.
int create_work_file(const std::string& path, int flags = O_WRONLY);
// Opens a work file that may already be there (a lock): never through a link; created
// (O_EXCL) when missing. Refuses (IoError) anything but a regular file.
int open_work_file(const std::string& path);

// The claim of a job on PATH: PATH.partial opened (created when missing) without
// following a link, checked to be a regular file with a single link, and locked
// (flock, exclusive) for as long as the claim lives. A second process that claims the
// same output is refused (UsageError) while the first runs; the kernel drops the
// lock when a process dies. A job takes the claim before any work and hands it to
// its writer (OutputFile shares the locked descriptor), so the output is its own from
// start to rename. The destructor removes PATH.partial only when this claim created
// it and nothing was written to it.
class OutputClaim {
 public:
  // A file the user named (kNamed) replaces an existing PATH at the end. A file written
  // beside it under a name the tool chose (kBeside: the .h5 of an .xdmf, the .ele of a
  // .node) may replace an existing PATH only when `main`, the named file, exists too
  // (a rerun of the same command); otherwise PATH is the user's and is refused.
  enum class Kind { kNamed, kBeside };
  explicit OutputClaim(std::string path, Kind kind = Kind::kNamed, const std::string& main = {});
  ~OutputClaim();
  OutputClaim(const OutputClaim&) = delete;
  OutputClaim& operator=(const OutputClaim&) = delete;

  const std::string& path() const { return path_; }
  int fd() const { return fd_; }
  bool created() const { return created_; }  // PATH.partial did not exist before

 private:
  std::string path_, partial_;
  int fd_ = -1;
  bool created_ = false;
};

// The partial output of a job as another process of the same job opens it to write
// its own part with pwrite (a rank under MPI: its sorted points, its frames): opened
// for reading and writing (a part may be moved in place) without following a link,
// never created or truncated, and refused
// (IoError) unless it is a regular file and the very file, by (st_dev, st_ino), that
// the job's claim holds. Closed on destruction.
class OutputPart {
 public:
  using Identity = std::pair<std::uint64_t, std::uint64_t>;  // (st_dev, st_ino)
  OutputPart(const std::string& partial_path, Identity identity);
  ~OutputPart();
  OutputPart(const OutputPart&) = delete;
  OutputPart& operator=(const OutputPart&) = delete;
  int fd() const { return fd_; }
  const std::string& path() const { return path_; }
  // Writes n bytes at `offset`; IoError naming the file when it cannot.
  void write_at(const void* data, std::size_t n, std::uint64_t offset);
  // fdatasync; IoError when it fails.
  void sync();
  // The identity of the file behind an open descriptor (of the claim's, say).
  static Identity identity_of(int fd);

 private:
  std::string path_;
  int fd_ = -1;
};

// Reads exactly n bytes at `offset` of fd (retrying short reads and EINTR). False,
// with errno set (EIO at the end of the file), when it cannot.
bool pread_exactly(int fd, void* data, std::size_t n, std::uint64_t offset);
// Writes exactly n bytes at `offset` of fd (retrying short writes and EINTR). False,
// with errno set, when it cannot.
bool pwrite_exactly(int fd, const void* data, std::size_t n, std::uint64_t offset);

class OutputFile {
 public:
  // Creates (truncates) PATH.partial, under `claim` when given (its locked file),
  // else claiming PATH itself (see OutputClaim). Throws IoError, UsageError.
  explicit OutputFile(std::string path, std::size_t buffer_bytes = std::size_t(8) << 20,
                      const OutputClaim* claim = nullptr);
  // Reopens an existing PATH.partial for a resumed job: keeps its first `keep` bytes
  // (it must have at least that many) and appends after them. Throws IoError.
  static std::unique_ptr<OutputFile> reopen(std::string path, std::uint64_t keep,
                                            std::size_t buffer_bytes = std::size_t(8) << 20,
                                            const OutputClaim* claim = nullptr);
  // Standard output, for a container streamed to a pipe ("-o -"): bytes are only
  // appended, commit() flushes (no fsync, no rename), and nothing is ever removed or
  // read back. Throws UsageError when stdout is a terminal.
  static std::unique_ptr<OutputFile> to_stdout(std::size_t buffer_bytes = std::size_t(8) << 20);
  ~OutputFile();
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;

  void write(const void* data, std::size_t n);
  void write(std::string_view s) { write(s.data(), s.size()); }
  // Room for n bytes in the buffer, to fill and then advance(n). The buffer grows to n
  // bytes when n is larger.
  char* reserve(std::size_t n);
  void advance(std::size_t n) { used_ += n; }

  std::size_t buffer_bytes() const { return cap_; }
  // Bytes written so far (buffered ones included): the offset of the next byte.
  std::uint64_t offset() const { return flushed_ + used_; }
  void flush();
  void sync();  // flush + fsync
  // Overwrites `n` bytes already written at `offset` (offset + n <= offset()): headers
  // whose values are known only at the end. Flushes first. Not on standard output.
  void write_at(std::uint64_t offset, const void* data, std::size_t n);
  // The next n bytes were written into PATH.partial by other processes (pwrite, from
  // offset() on): flushes, checks that the file holds them, and goes on after them.
  // Not on standard output.
  void skip(std::uint64_t n);
  // Reads back `n` bytes at `offset` (< the flushed size), for a resumed writer's checks.
  void read_at(std::uint64_t offset, void* data, std::size_t n) const;
  // Flushes, syncs (if asked), closes and renames PATH.partial to PATH.
  void commit(bool sync = true);
  // Whether a destructor without commit() leaves PATH.partial in place (true) or
  // removes it (false, the default).
  void keep_on_failure(bool keep) { keep_on_failure_ = keep; }
  // Drops every byte (buffered and written: PATH.partial truncated to 0) and leaves the
  // empty file in place on destruction, for the claim that made it (which removes it
  // empty) or a later writer under that claim. IoError when it cannot. Not on standard
  // output.
  void discard();

  const std::string& path() const { return path_; }
  const std::string& partial_path() const { return partial_; }

 private:
  OutputFile(std::string path, std::size_t buffer_bytes, int fd, std::uint64_t flushed);

  std::string path_, partial_;
  int fd_ = -1;
  bool stream_ = false;  // standard output: no partial file, no rename, no read-back
  // Set when this file claimed PATH itself (no claim given): the lock lives as long.
  std::unique_ptr<OutputClaim> own_claim_;
  bool committed_ = false;
  bool keep_on_failure_ = false;
  std::unique_ptr<char[]> buf_;
  std::size_t cap_ = 0, used_ = 0;
  std::uint64_t flushed_ = 0;
};

}  // namespace tetstream::io
