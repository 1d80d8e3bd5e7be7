#pragma once
// Helpers for the point reader tests: a scratch directory, byte builders, and reading a
// file in small odd chunks (so records and lines straddle block boundaries).
#include "io/point_reader.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace tetstream::io {

class TempDir {
 public:
  TempDir() {
    std::string tmpl = (std::filesystem::temp_directory_path() / "tetstream_point_io_XXXXXX").string();
    path_ = ::mkdtemp(tmpl.data());
  }
  ~TempDir() { std::filesystem::remove_all(path_); }
  std::string file(const std::string& name) const { return (path_ / name).string(); }

 private:
  std::filesystem::path path_;
};

inline void write_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
}

template <class T>
std::string le_bytes(T v) {  // little-endian bytes of v
  std::string s(sizeof(T), '\0');
  std::memcpy(s.data(), &v, sizeof(T));
  if constexpr (std::endian::native == std::endian::big) std::reverse(s.begin(), s.end());
  return s;
}
template <class T>
std::string be_bytes(T v) {
  std::string s = le_bytes(v);
  std::reverse(s.begin(), s.end());
  return s;
}

// Reads everything in small, odd chunks, with a tiny read block, so records and lines
// straddle block boundaries.
inline std::vector<double> read_all(const std::string& path, PointReadOptions opt = {}, std::size_t chunk = 7) {
  opt.block_bytes = 4096;
  auto r = open_points(path, opt);
  std::vector<double> out, buf(3 * chunk);
  while (std::size_t n = r->read(buf.data(), chunk)) out.insert(out.end(), buf.begin(), buf.begin() + 3 * n);
  EXPECT_EQ(r->read(buf.data(), chunk), 0u);  // stays at the end
  return out;
}

// Skipping n points then reading the rest gives what reading everything and dropping
// the first n gives, for n from 0 to past the end; skip() returns how many it passed.
// (How a rank of a distributed job reaches its range: seeking where the format allows.)
inline void expect_skip_is_read_and_drop(const std::string& path, PointReadOptions opt = {}) {
  const std::vector<double> all = read_all(path, opt);
  const std::size_t count = all.size() / 3;
  opt.block_bytes = 4096;
  for (std::size_t n : {std::size_t(0), std::size_t(1), std::size_t(2), count / 2, count - 1, count, count + 5}) {
    if (n > count + 5) continue;  // (count - 1 when count is 0)
    auto r = open_points(path, opt);
    const std::size_t skipped = std::min(n, count);
    EXPECT_EQ(r->skip(n), skipped) << path << " skip " << n;
    EXPECT_EQ(r->points_read(), skipped) << path << " skip " << n;
    std::vector<double> rest, buf(3 * 7);
    while (std::size_t k = r->read(buf.data(), 7)) rest.insert(rest.end(), buf.begin(), buf.begin() + 3 * k);
    EXPECT_EQ(rest, std::vector<double>(all.begin() + std::ptrdiff_t(3 * skipped), all.end())) << path << " skip " << n;
    EXPECT_EQ(r->points_read(), count) << path << " skip " << n;
  }
}

// The message of the InputError that reading `path` throws ("" if none).
inline std::string read_error(const std::string& path, PointReadOptions opt = {}) {
  try {
    read_all(path, opt);
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << "one line: " << e.what();
    return e.what();
  }
  return "";
}

// A .npy file: preamble, header dict padded to 64 bytes, then `data`.
inline std::string npy_bytes(int major, const std::string& descr, const std::string& shape, const std::string& data,
                             const std::string& fortran = "False") {
  std::string dict = "{'descr': '" + descr + "', 'fortran_order': " + fortran + ", 'shape': " + shape + ", }";
  const std::size_t pre = major == 1 ? 10 : 12;
  while ((pre + dict.size() + 1) % 64) dict += ' ';
  dict += '\n';
  std::string s = "\x93NUMPY";
  s += char(major);
  s += '\0';
  if (major == 1)
    s += le_bytes<std::uint16_t>(std::uint16_t(dict.size()));
  else
    s += le_bytes<std::uint32_t>(std::uint32_t(dict.size()));
  return s + dict + data;
}

#define EXPECT_INPUT_ERROR(path, opt, where, what)          \
  do {                                                      \
    const std::string msg_ = read_error(path, opt);         \
    EXPECT_NE(msg_, "") << "no error for " << path;         \
    EXPECT_NE(msg_.find(path), std::string::npos) << msg_;  \
    EXPECT_NE(msg_.find(where), std::string::npos) << msg_; \
    EXPECT_NE(msg_.find(what), std::string::npos) << msg_;  \
  } while (0)

}  // namespace tetstream::io
