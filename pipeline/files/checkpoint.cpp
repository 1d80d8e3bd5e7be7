#include "pipeline/files/checkpoint.hpp"

#include "io/output_file.hpp"

#include "core/error.hpp"
#include "io/tet_container.hpp"
#include "pipeline/files/temp_files.hpp"

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <spdlog/spdlog.h>
#include <vector>
#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

namespace tetstream::pipeline {

namespace {

std::string errno_text() { return std::strerror(errno); }

constexpr const char* kFormat = "tetstream-checkpoint";

std::uint32_t state_crc(const nlohmann::json& body) {
  const std::string text = body.dump();
  return io::crc32c(text.data(), text.size());
}

}  // namespace

nlohmann::json fingerprint_file(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY);
  if (fd < 0) throw IoError(path + ": cannot open: " + errno_text());
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    const int err = errno;
    ::close(fd);
    errno = err;
    throw IoError(path + ": cannot stat: " + errno_text());
  }
  const std::uint64_t size = std::uint64_t(st.st_size);
  const std::uint64_t mtime_ns = std::uint64_t(st.st_mtim.tv_sec) * 1000000000ull + std::uint64_t(st.st_mtim.tv_nsec);
  // 64 samples of 4 KiB spread evenly, the first at 0 and the last at the end.
  constexpr std::uint64_t kSamples = 64, kSample = 4096;
  std::vector<char> buf(kSample);
  std::uint32_t crc = 0;
  for (std::uint64_t i = 0; i < kSamples; ++i) {
    const std::uint64_t at = size > kSample ? (size - kSample) * i / (kSamples - 1) : 0;
    const ssize_t n = ::pread(fd, buf.data(), kSample, off_t(at));
    if (n < 0) {
      const int err = errno;
      ::close(fd);
      errno = err;
      throw IoError(path + ": read failed: " + errno_text());
    }
    crc = io::crc32c(buf.data(), std::size_t(n), crc);
    if (size <= kSample) break;
  }
  ::close(fd);
  return {{"size", size}, {"mtime_ns", mtime_ns}, {"sample_crc32c", crc}};
}

bool Checkpoint::exists() const {
  std::error_code ec;
  return std::filesystem::exists(path(state_name_), ec);
}

void Checkpoint::join() const {
  struct stat st {};
  if (::lstat(dir_.c_str(), &st) != 0 || !S_ISDIR(st.st_mode))
    throw IoError(dir_ + ": not the job's checkpoint directory (missing, or not a directory)");
  if (::lstat(path(WorkDir::kMarker).c_str(), &st) != 0 || !S_ISREG(st.st_mode))
    throw IoError(dir_ + ": not a directory tetstream made (no marker)");
}

void Checkpoint::create_and_lock() {
  if (!work_) work_.emplace(WorkDir::open_or_create(dir_));
}

void Checkpoint::clear() const {
  if (work_) work_->clear();
}

nlohmann::json Checkpoint::load() const {
  const std::string file = path(state_name_);
  std::ifstream in(file, std::ios::binary);
  if (!in) throw IoError(file + ": cannot open: " + errno_text());
  std::stringstream text;
  text << in.rdbuf();
  nlohmann::json state;
  try {
    state = nlohmann::json::parse(text.str());
  } catch (const nlohmann::json::exception& e) {
    throw DamagedCheckpoint(file + ": damaged checkpoint (not valid JSON: " + std::string(e.what()) + ")");
  }
  if (!state.is_object() || state.value("format", "") != kFormat || !state.contains("crc32c"))
    throw DamagedCheckpoint(file + ": not a tetstream checkpoint");
  if (state.value("version", 0) != kVersion)
    throw DamagedCheckpoint(file + ": checkpoint version " + std::to_string(state.value("version", 0)) +
                            ", this tetstream reads version " + std::to_string(kVersion));
  const std::uint32_t stored = state["crc32c"].get<std::uint32_t>();
  state.erase("crc32c");
  if (state_crc(state) != stored) throw DamagedCheckpoint(file + ": damaged checkpoint (checksum mismatch)");
  return state;
}

void Checkpoint::save(nlohmann::json state) {
  state["format"] = kFormat;
  state["version"] = kVersion;
  state.erase("crc32c");
  state["crc32c"] = state_crc(state);
  const std::string text = state.dump(1);
  write_file_atomically(dir_, state_name_, text.data(), text.size());
}

void Checkpoint::remove() {
  if (work_ && !work_->remove()) spdlog::warn("{} is left in place: it holds files that tetstream did not write", dir_);
  work_.reset();
}

void write_file_atomically(const std::string& dir, const std::string& name, const void* data, std::size_t bytes) {
  const std::string final_path = dir + "/" + name, tmp_path = final_path + ".tmp";
  {
    BinaryFile f(tmp_path, "wb");
    f.write(data, 1, bytes);
    f.close(/*sync=*/true);
  }
  if (std::rename(tmp_path.c_str(), final_path.c_str()) != 0)
    throw IoError(final_path + ": cannot rename into place: " + errno_text());
  sync_directory(dir);
}

void read_file_exactly(const std::string& path, void* data, std::size_t bytes, std::uint32_t crc) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw DamagedCheckpoint(path + ": damaged checkpoint (the file is missing)");
  BinaryFile f(path, "rb");
  const std::size_t n = f.read(data, 1, bytes);
  char extra;
  if (n != bytes || f.read(&extra, 1, 1) != 0)
    throw DamagedCheckpoint(path + ": damaged checkpoint (expected " + std::to_string(bytes) + " bytes)");
  if (io::crc32c(data, bytes) != crc) throw DamagedCheckpoint(path + ": damaged checkpoint (checksum mismatch)");
}

bool file_matches(const std::string& path, std::uint64_t bytes, std::uint32_t crc) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && std::uint64_t(st.st_size) == bytes && region_matches(path, 0, bytes, crc);
}

bool region_matches(const std::string& path, std::uint64_t offset, std::uint64_t bytes, std::uint32_t crc) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
  if (fd < 0) return false;
  std::vector<char> buf(std::size_t(1) << 20);
  std::uint32_t c = 0;
  for (std::uint64_t done = 0; done < bytes;) {
    const std::size_t n = std::size_t(std::min<std::uint64_t>(buf.size(), bytes - done));
    if (!io::pread_exactly(fd, buf.data(), n, offset + done)) {
      ::close(fd);
      return false;  // short: the region is not all there
    }
    c = io::crc32c(buf.data(), n, c);
    done += n;
    // Hand the pages back: a resume checks files larger than memory.
    if (done % (std::uint64_t(64) << 20) == 0) ::posix_fadvise(fd, 0, off_t(offset + done), POSIX_FADV_DONTNEED);
  }
  ::close(fd);
  return c == crc;
}

}  // namespace tetstream::pipeline
