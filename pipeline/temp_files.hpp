#pragma once
// Temporary files of a job: one private directory under --tmpdir, removed with
// everything in it when the job ends, whether it succeeds or fails.
#include <cstddef>
#include <cstdio>
#include <string>

namespace tetstream::pipeline {

class TempDir {
 public:
  // Creates PARENT/PREFIX-XXXXXX. Throws IoError when it cannot.
  TempDir(const std::string& parent, const std::string& prefix);
  ~TempDir();  // removes the directory and its contents
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  const std::string& dir() const { return dir_; }
  std::string path(const std::string& name) const { return dir_ + "/" + name; }

 private:
  std::string dir_;
};

void remove_file(const std::string& path);  // ignores a missing file
// fsync of a directory, so that a rename or a new file in it survives a crash.
void sync_directory(const std::string& dir);

// Hands the pages of [data, data + bytes) of a read-only file mapping back to the page
// cache (madvise MADV_DONTNEED), so that a linear pass over a mapped file larger than
// memory keeps a bounded resident set; a later access faults them back in.
void release_mapped_pages(const void* data, std::size_t bytes);

// A binary file with checked I/O: every failure (ENOSPC, EIO) throws IoError naming
// the file, so no stage carries on with a short write.
class BinaryFile {
 public:
  BinaryFile(const std::string& path, const char* mode);  // fopen modes "rb", "wb"
  ~BinaryFile();
  BinaryFile(const BinaryFile&) = delete;
  BinaryFile& operator=(const BinaryFile&) = delete;

  void write(const void* data, std::size_t size, std::size_t count);
  // Reads up to `count` items; returns how many (fewer only at the end of the file).
  std::size_t read(void* data, std::size_t size, std::size_t count);
  // Flushes (and with `sync`, fsyncs: the data survives a crash of the machine);
  // throws IoError when the data did not reach the file.
  void close(bool sync = false);

 private:
  std::string path_;
  std::FILE* f_ = nullptr;
};

}  // namespace tetstream::pipeline
