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
  struct stat st{};
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
    if (!f8 && !f4) throw InputError::at_byte(path_, 10, "masses must be a little-endian float64 or float32 .npy array");
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
    throw InputError::at_byte(path_, data_offset_, what + " holds " + std::to_string(have) +
                                                      " values, the container's input had " + std::to_string(count_));
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
    std::uint32_t u = std::uint32_t(p[0]) | std::uint32_t(p[1]) << 8 | std::uint32_t(p[2]) << 16 | std::uint32_t(p[3]) << 24;
    float f;
    std::memcpy(&f, &u, 4);
    v = f;
  }
  if (!std::isfinite(v) || v <= 0.0)
    throw InputError::at_byte(path_, data_offset_ + index * item_,
                              "mass " + std::to_string(v) + " of point " + std::to_string(index) + " is not finite and > 0");
  return v;
}

}  // namespace tetstream::io
