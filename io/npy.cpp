#include "io/npy.hpp"

#include "io/output_file.hpp"

#include <stdexcept>

namespace tetstream::io {

std::string npy_header(const std::string& descr, const std::string& shape, std::size_t total) {
  std::string dict = "{'descr': '" + descr + "', 'fortran_order': False, 'shape': (" + shape + "), }";
  const std::size_t len = 10 + dict.size() + 1;  // preamble, dict, '\n'
  const std::size_t want = total ? total : (len + 63) / 64 * 64;
  if (want < len || want - 10 > 0xffff) throw std::logic_error("npy header does not fit: " + dict);
  dict.append(want - len, ' ');
  dict.push_back('\n');
  std::string h = "\x93NUMPY";
  h.push_back('\x01');
  h.push_back('\x00');
  const std::size_t hl = dict.size();
  h.push_back(static_cast<char>(hl & 0xff));
  h.push_back(static_cast<char>(hl >> 8));
  return h + dict;
}

std::size_t npy_item_bytes(const std::string& descr) {
  if (descr.size() < 3) throw std::logic_error("bad npy descr " + descr);
  return std::size_t(std::stoul(descr.substr(2)));
}

NpyArrayWriter::NpyArrayWriter(std::string path, std::string descr, std::vector<std::uint64_t> shape)
    : path_(std::move(path)) {
  std::string text;
  expected_ = npy_item_bytes(descr);
  for (std::size_t i = 0; i < shape.size(); ++i) {
    text += (i ? ", " : "") + std::to_string(shape[i]);
    expected_ *= shape[i];
  }
  if (shape.size() == 1) text += ",";  // a 1-tuple in Python needs the comma
  file_ = std::make_unique<OutputFile>(path_);
  file_->write(npy_header(descr, text));
}

NpyArrayWriter::~NpyArrayWriter() = default;

void NpyArrayWriter::write(const void* data, std::size_t bytes) {
  file_->write(data, bytes);
  written_ += bytes;
}

void NpyArrayWriter::commit() {
  if (written_ != expected_)
    throw std::logic_error(path_ + ": wrote " + std::to_string(written_) + " data bytes, the shape needs " +
                           std::to_string(expected_));
  file_->commit();
}

}  // namespace tetstream::io

#include "core/error.hpp"

#include <cmath>
#include <cstring>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace tetstream::io {

ScalarFileReader::ScalarFileReader(std::string path, std::uint64_t count) : path_(std::move(path)), count_(count) {
  fd_ = ::open(path_.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) throw InputError(path_ + ": cannot open: " + std::strerror(errno));
  note_input_fd(fd_);
  struct stat st {};
  ::fstat(fd_, &st);
  const std::uint64_t size = std::uint64_t(st.st_size);
  unsigned char pre[10] = {};
  const bool npy = size >= 10 && pread_exactly(fd_, pre, 10, 0) && std::memcmp(pre, "\x93NUMPY", 6) == 0;
  std::string what = "raw float64";
  if (npy) {
    if (pre[6] != 1) throw InputError::at_byte(path_, 6, "only .npy format version 1 is read here");
    const std::uint64_t hl = pre[8] | std::uint64_t(pre[9]) << 8;
    std::string h(hl, '\0');
    if (!pread_exactly(fd_, h.data(), hl, 10)) throw InputError::at_byte(path_, 10, "truncated .npy header");
    data_offset_ = 10 + hl;
    const bool f8 = h.find("'<f8'") != std::string::npos, f4 = h.find("'<f4'") != std::string::npos;
    if (!f8 && !f4)
      throw InputError::at_byte(path_, 10, "masses must be a little-endian float64 or float32 .npy array");
    if (h.find("'fortran_order': True") != std::string::npos)
      throw InputError::at_byte(path_, 10, "Fortran-ordered .npy arrays are not read");
    item_ = f8 ? 8 : 4;
    const std::size_t s = h.find("'shape': (");
    const std::string shape = s == std::string::npos ? "" : h.substr(s + 10, h.find(')', s) - s - 10);
    if (shape.find(',') == std::string::npos || shape.find(',') + 1 < shape.find_last_not_of(' ') + 1)
      throw InputError::at_byte(path_, 10, "masses must be a 1-D array, not shape (" + shape + ")");
    what = ".npy array of " + std::string(f8 ? "float64" : "float32");
  }
  const std::uint64_t have = (size - data_offset_) / item_;
  if (have != count_ || (size - data_offset_) % item_ != 0)
    throw InputError::at_byte(
        path_, data_offset_,
        what + " holds " + std::to_string(have) + " values, the container's input had " + std::to_string(count_));
  buf_.resize(std::size_t(1) << 20);
}

ScalarFileReader::~ScalarFileReader() {
  if (fd_ >= 0) ::close(fd_);
}

void ScalarFileReader::fill(std::uint64_t index) {
  buf_first_ = index;
  buf_count_ = std::min<std::uint64_t>(buf_.size() / item_, count_ - index);
  if (!pread_exactly(fd_, buf_.data(), std::size_t(buf_count_ * item_), data_offset_ + index * item_))
    throw IoError(path_ + ": read failed: " + std::strerror(errno));
}

double ScalarFileReader::at(std::uint64_t index) {
  if (index >= count_) throw std::logic_error(path_ + ": mass index out of range");
  if (index < buf_first_ || index >= buf_first_ + buf_count_) fill(index);
  const unsigned char* p = buf_.data() + (index - buf_first_) * item_;
  double v;
  if (item_ == 8) {
    std::uint64_t u = 0;
    for (int i = 7; i >= 0; --i) u = u << 8 | p[i];
    std::memcpy(&v, &u, 8);
  } else {
    std::uint32_t u =
        std::uint32_t(p[0]) | std::uint32_t(p[1]) << 8 | std::uint32_t(p[2]) << 16 | std::uint32_t(p[3]) << 24;
    float f;
    std::memcpy(&f, &u, 4);
    v = f;
  }
  if (!std::isfinite(v) || v <= 0.0)
    throw InputError::at_byte(
        path_, data_offset_ + index * item_,
        "mass " + std::to_string(v) + " of point " + std::to_string(index) + " is not finite and > 0");
  return v;
}

}  // namespace tetstream::io

namespace tetstream::io {

namespace {

// Little-endian bytes p[0..k) as an unsigned integer.
std::uint64_t le_unsigned(const unsigned char* p, std::size_t k) {
  std::uint64_t u = 0;
  for (std::size_t i = k; i-- > 0;) u = u << 8 | p[i];
  return u;
}

}  // namespace

std::vector<double> read_npy_values(const std::string& path, std::uint64_t count) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw InputError(path + ": cannot open: " + std::strerror(errno));
  struct Close {
    int fd;
    ~Close() { ::close(fd); }
  } close_fd{fd};
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) throw InputError(path + ": not a regular file");
  const std::uint64_t size = std::uint64_t(st.st_size);
  unsigned char pre[12] = {};
  if (size < 10 || !pread_exactly(fd, pre, 10, 0) || std::memcmp(pre, "\x93NUMPY", 6) != 0)
    throw InputError::at_byte(path, 0, "not a .npy file (no \\x93NUMPY magic)");
  // Version 1: a 2-byte header length; 2 and 3: a 4-byte one.
  std::uint64_t header_at = 10, hl = pre[8] | std::uint64_t(pre[9]) << 8;
  if (pre[6] >= 2) {
    if (!pread_exactly(fd, pre + 10, 2, 10)) throw InputError::at_byte(path, 10, "truncated .npy header");
    header_at = 12, hl = le_unsigned(pre + 8, 4);
  }
  if (hl > size - header_at) throw InputError::at_byte(path, header_at, "truncated .npy header");
  std::string h(std::size_t(hl), '\0');
  if (!pread_exactly(fd, h.data(), h.size(), header_at))
    throw InputError::at_byte(path, header_at, "truncated .npy header");
  const std::uint64_t data_at = header_at + hl;
  const std::size_t d = h.find("'descr': '");
  const std::string descr = d == std::string::npos ? "" : h.substr(d + 10, h.find('\'', d + 10) - d - 10);
  // '<f8', '<i4', '|u1'...: the byte order, the kind, the item size.
  const bool known = descr.size() == 3 && (descr[0] == '<' || (descr[0] == '|' && descr[2] == '1')) &&
                     (descr[1] == 'f' ? (descr[2] == '4' || descr[2] == '8')
                                      : (descr[1] == 'i' || descr[1] == 'u') &&
                                            std::string("1248").find(descr[2]) != std::string::npos);
  if (!known) {
    throw InputError::at_byte(path, header_at,
                              "dtype '" + descr + "' is not one of float64, float32 or a " +
                                  "little-endian integer (convert it with numpy's astype)");
  }
  if (h.find("'fortran_order': True") != std::string::npos)
    throw InputError::at_byte(path, header_at, "Fortran-ordered .npy arrays are not read");
  const std::size_t s = h.find("'shape': (");
  const std::string shape = s == std::string::npos ? "" : h.substr(s + 10, h.find(')', s) - s - 10);
  const std::size_t comma = shape.find(',');
  if (comma == std::string::npos || shape.find_first_not_of(' ', comma + 1) != std::string::npos)
    throw InputError::at_byte(path, header_at, "a 1-D array is needed, not shape (" + shape + ")");
  const std::size_t item = std::size_t(descr[2] - '0');
  const std::uint64_t have = (size - data_at) / item;
  if (have != count || (size - data_at) % item != 0) {
    throw InputError::at_byte(
        path, data_at,
        "holds " + std::to_string(have) + " values, the container has " + std::to_string(count) + " points");
  }
  std::vector<unsigned char> bytes(std::size_t(count) * item);
  if (!pread_exactly(fd, bytes.data(), bytes.size(), data_at))
    throw IoError(path + ": read failed: " + std::strerror(errno));
  std::vector<double> values(static_cast<std::size_t>(count));
  constexpr double kExact = 9007199254740992.0;  // 2^53: beyond it a double skips integers
  for (std::size_t i = 0; i < values.size(); ++i) {
    const std::uint64_t u = le_unsigned(bytes.data() + i * item, item);
    double v;
    if (descr[1] == 'f') {
      if (item == 8) {
        std::memcpy(&v, &u, 8);
      } else {
        const std::uint32_t u32 = std::uint32_t(u);
        float f;
        std::memcpy(&f, &u32, 4);
        v = f;
      }
    } else if (descr[1] == 'u') {
      v = double(u);
      if (u > std::uint64_t(kExact))
        throw InputError::at_byte(path, data_at + i * item,
                                  "integer " + std::to_string(u) + " is not exact in float64");
    } else {
      const unsigned shift = unsigned(64 - 8 * item);
      const std::int64_t x = std::int64_t(u << shift) >> shift;  // sign-extend
      v = double(x);
      if (x > std::int64_t(kExact) || x < -std::int64_t(kExact))
        throw InputError::at_byte(path, data_at + i * item,
                                  "integer " + std::to_string(x) + " is not exact in float64");
    }
    values[i] = v;
  }
  return values;
}

}  // namespace tetstream::io
