#pragma once
// Temporary files of a job: one private directory under --tmpdir, removed with
// everything in it when the job ends, whether it succeeds or fails.
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "pipeline/files/work_dir.hpp"

namespace tetstream::pipeline {

// A WorkDir (pipeline/work_dir.hpp) made for one process and removed when it ends:
// the job's own files are unlinked, nothing else. A process killed with -9 leaves it
// behind unlocked, and the next run in the same parent (or `tetstream clean`) removes it.
class TempDir {
 public:
  // Creates PARENT/PREFIX-XXXXXX. Throws IoError when it cannot.
  TempDir(const std::string& parent, const std::string& prefix) : dir_(WorkDir::create_unique(parent, prefix)) {}
  ~TempDir() { dir_.remove(); }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  const std::string& dir() const { return dir_.dir(); }
  std::string path(const std::string& name) const { return dir_.path(name); }

 private:
  WorkDir dir_;
};

void remove_file(const std::string& path);  // ignores a missing file
// fsync of a directory, so that a rename or a new file in it survives a crash.
void sync_directory(const std::string& dir);

// Hands the pages of [data, data + bytes) of a read-only file mapping back to the page
// cache (madvise MADV_DONTNEED), so that a linear pass over a mapped file larger than
// memory keeps a bounded resident set; a later access faults them back in.
void release_mapped_pages(const void* data, std::size_t bytes);

// Bounds what scattered reads of a read-only file mapping keep resident. A read that
// faults can map much more than its page: the kernel maps the whole folio of the page
// cache around it, and a file written in large chunks sits in folios of up to 2 MiB
// (here one byte read mapped 2048 KiB; 64 KiB, the fault-around window, elsewhere in
// the same file). So the unit of residency is the 2 MiB region of the file (folios
// are aligned in the file, at most 2 MiB on x86-64): touch() records the region of
// each read, and when a read needs a region beyond max_regions, the least recently
// read one is handed back first.
//
// A region that is read only here and there (a huge ball's query takes a point from
// each of hundreds of regions) is not worth mapping: read() copies such points with
// pread, and maps a region only once it has been read kAdmitReads times lately.
//
// Shared by the threads that read the mapping: a region that several read is held
// once, and one thread's release never leaves the others' pages unaccounted for long.
// (One tracker per thread, each a share, would make the threads release each
// other's regions: the zones of a segment read the same label range, and every
// release costs a TLB shootdown on every core.) A read is a relaxed load and,
// once per epoch, a compare-and-swap; a new region takes a lock. The clock is an
// epoch that each new region advances, so "least recently read" is by epochs. A read
// that races with the release of its region maps pages that count again at the next
// read of that region: a few regions at most, until then or until the whole mapping
// is handed back (the job does so after each zone).
class MappedRegions {
 public:
  static constexpr int kRegionShift = 21;
  static constexpr std::size_t kRegionBytes = std::size_t(1) << kRegionShift;
  // `data` is the mapping's start (file offset 0), `bytes` its length. With the
  // mapped file's `path`, read() may bypass the mapping (throws IoError when the file
  // cannot be opened).
  MappedRegions(const void* data, std::size_t bytes, std::size_t max_regions, const std::string& path = {});
  ~MappedRegions();
  MappedRegions(const MappedRegions&) = delete;
  MappedRegions& operator=(const MappedRegions&) = delete;

  // Copies `bytes` at p, inside the mapping, to `out`. From the mapping when p's region
  // is held, or has been read kAdmitReads times lately (it is then held, as touch()
  // would); otherwise with pread, which maps nothing. A huge ball's query reads a point
  // here and there over hundreds of regions, and mapping each for one read would cost
  // a release a query. Throws IoError when
  // pread fails. Without a path, the same as touch() and a copy.
  void read(const void* p, void* out, std::size_t bytes);
  static constexpr std::uint32_t kAdmitReads = 8;

  void touch(const void* p) {
    const std::size_t r = std::size_t(static_cast<const char*>(p) - base_) >> kRegionShift;
    const std::uint64_t now = clock_.load(std::memory_order_relaxed);
    std::uint64_t last = last_read_[r].load(std::memory_order_relaxed);
    // A compare-and-swap, not a store: a store could bring back a region that another
    // thread has just released (set to 0), which would then be marked held but never
    // released again: held regions would pile up past their cap.
    while (last != now) {
      if (last == 0) return hold(r);
      if (last_read_[r].compare_exchange_weak(last, now, std::memory_order_relaxed)) return;
    }
  }
  // Hands every held region back.
  void release_all();
  std::size_t held() const;
  std::uint64_t releases() const { return releases_.load(std::memory_order_relaxed); }

 private:
  void hold(std::size_t region);            // makes room first, unless another thread held it meanwhile
  void release_region(std::size_t region);  // under the lock; the caller drops it from held_
  // Whether a read of region r should go through the mapping: it is held, or this
  // read makes kAdmitReads recent ones (then it is to be held).
  bool worth_mapping(std::size_t r);
  const char* base_;
  std::size_t bytes_, max_regions_;
  std::string path_;
  int fd_ = -1;
  // Per region not held: the epoch of its first recent unmapped read (high 40 bits)
  // and how many since (low 24); reads older than max_regions epochs are forgotten.
  std::unique_ptr<std::atomic<std::uint64_t>[]> cold_reads_;
  std::unique_ptr<std::atomic<std::uint64_t>[]> last_read_;  // per region: epoch of its last read, 0 when not held
  std::atomic<std::uint64_t> clock_{1}, releases_{0};
  mutable std::mutex mutex_;       // over held_ and the holds and releases
  std::vector<std::size_t> held_;  // the regions with last_read_ != 0
};

// A binary file with checked I/O: every failure (ENOSPC, EIO) throws IoError naming
// the file, so no stage carries on with a short write.
class BinaryFile {
 public:
  // "rb"; "r+b" (an existing file, not through a link); "wb": a new work file
  // (io::create_work_file: a link or file at its name is replaced, never written).
  BinaryFile(const std::string& path, const char* mode);
  ~BinaryFile();
  BinaryFile(const BinaryFile&) = delete;
  BinaryFile& operator=(const BinaryFile&) = delete;

  void write(const void* data, std::size_t size, std::size_t count);
  // Reads up to `count` items; returns how many (fewer only at the end of the file).
  std::size_t read(void* data, std::size_t size, std::size_t count);
  // Flushes (and with `sync`, fsyncs: the data survives a crash of the machine);
  // throws IoError when the data did not reach the file.
  void close(bool sync = false);
  // CRC32C (io::crc32c) of every byte written so far: a checkpoint records it, and a
  // resumed job checks the file against it before trusting it.
  std::uint32_t crc() const { return crc_; }
  // Gives the file's blocks before `offset` back to the filesystem (a hole punched,
  // the size kept: fallocate PUNCH_HOLE | KEEP_SIZE), for a file read once front to
  // back whose read part is no longer needed. Silently nothing where the filesystem
  // cannot punch (EOPNOTSUPP: the space then comes back when the file is removed).
  // Throws IoError on any other failure.
  void give_back_before(std::uint64_t offset);

 private:
  std::string path_;
  std::FILE* f_ = nullptr;
  std::uint32_t crc_ = 0;
  std::uint64_t given_back_ = 0;  // bytes [0, given_back_) are a hole
  bool can_punch_ = true;
};

}  // namespace tetstream::pipeline
