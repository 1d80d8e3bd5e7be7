#include "io/point_writer.hpp"

#include "io/npy.hpp"
#include "io/output_file.hpp"

#include "core/error.hpp"

#include <algorithm>
#include <bit>
#include <cerrno>
#include <charconv>
#include <cstdio>
#include <cstring>
#include <fcntl.h>
#include <stdexcept>
#include <unistd.h>

namespace tetstream::io {

namespace {
constexpr bool kHostLittle = std::endian::native == std::endian::little;
constexpr int kCountWidth = 20;  // digits reserved for a count patched at commit()
}  // namespace

PointWriter::~PointWriter() {
  if (fd_ >= 0 && !to_stdout_) ::close(fd_);
  if (!committed_ && !tmp_path_.empty()) ::unlink(tmp_path_.c_str());
}

PointWriter::PointWriter() = default;

void PointWriter::open(const std::string& path, std::size_t buffer_bytes) {
  path_ = path;
  if (is_std_stream(path)) {
    to_stdout_ = true;
    fd_ = STDOUT_FILENO;
  } else {
    // The claim refuses a link, a device, an input, and a second job on the same
    // output; the writer writes through the claim's locked descriptor.
    claim_ = std::make_unique<OutputClaim>(path);
    fd_ = ::fcntl(claim_->fd(), F_DUPFD_CLOEXEC, 0);
    if (fd_ < 0) throw IoError("cannot duplicate the descriptor of " + path + ".partial: " + std::strerror(errno));
    tmp_path_ = path + ".partial";
    if (::ftruncate(fd_, 0) != 0) throw IoError("cannot truncate " + tmp_path_ + ": " + std::strerror(errno));
  }
  cap_ = buffer_bytes < 65536 ? 65536 : buffer_bytes;
  buf_.reset(new char[cap_]);
}

void PointWriter::flush() {
  const char* p = buf_.get();
  std::size_t left = used_;
  while (left > 0) {
    const ssize_t r = ::write(fd_, p, left);
    if (r < 0) {
      if (errno == EINTR) continue;
      throw IoError("cannot write " + (to_stdout_ ? std::string("<stdout>") : path_) + ": " + std::strerror(errno));
    }
    p += r;
    left -= static_cast<std::size_t>(r);
  }
  used_ = 0;
}

void PointWriter::put(const void* data, std::size_t n) {
  if (n == 0) return;  // an empty vector's data() may be null
  const char* p = static_cast<const char*>(data);
  bytes_ += n;
  if (used_ + n <= cap_) {
    std::memcpy(buf_.get() + used_, p, n);
    used_ += n;
    return;
  }
  // Fill the buffer up, write it, and pass big remainders straight through.
  const std::size_t head = cap_ - used_;
  std::memcpy(buf_.get() + used_, p, head);
  used_ = cap_;
  flush();
  p += head;
  n -= head;
  while (n >= cap_) {
    std::memcpy(buf_.get(), p, cap_);
    used_ = cap_;
    flush();
    p += cap_;
    n -= cap_;
  }
  std::memcpy(buf_.get(), p, n);
  used_ = n;
}

void PointWriter::pwrite_at(std::uint64_t offset, const void* data, std::size_t n) {
  if (to_stdout_) throw UsageError("cannot patch a header on stdout: the point count must be known");
  if (::pwrite(fd_, data, n, static_cast<off_t>(offset)) != static_cast<ssize_t>(n)) {
    throw IoError("cannot write " + path_ + ": " + std::strerror(errno));
  }
}

void PointWriter::write(const double* xyz, std::size_t n) {
  if (count_ != kUnknownCount && points_ + n > count_) {
    throw std::logic_error("PointWriter: more points written than the " + std::to_string(count_) + " declared");
  }
  encode(xyz, n);
  points_ += n;
}

void PointWriter::commit() {
  if (count_ != kUnknownCount && points_ != count_) {
    throw std::logic_error("PointWriter: " + std::to_string(points_) + " points written, " + std::to_string(count_) +
                           " declared");
  }
  finish();
  flush();
  if (to_stdout_) {
    committed_ = true;
    return;
  }
  if (::fsync(fd_) != 0) throw IoError("cannot write " + path_ + ": fsync failed: " + std::strerror(errno));
  if (::close(fd_) != 0) {
    fd_ = -1;
    throw IoError("cannot write " + path_ + ": " + std::strerror(errno));
  }
  fd_ = -1;
  if (::rename(tmp_path_.c_str(), path_.c_str()) != 0) {
    throw IoError("cannot rename " + tmp_path_ + " to " + path_ + ": " + std::strerror(errno));
  }
  note_input(path_);  // a later output of this process (--json-file) never replaces it
  committed_ = true;
}

namespace {

class RawWriter : public PointWriter {
 public:
  RawWriter(bool f32, bool big) : f32_(f32), swap_(big == kHostLittle) {}

 protected:
  void encode(const double* xyz, std::size_t n) override { encode_binary(xyz, 3 * n); }

  void encode_binary(const double* v, std::size_t count) {
    if (!f32_ && !swap_) {
      put(v, count * 8);
      return;
    }
    constexpr std::size_t kBatch = 4096;
    unsigned char scratch[kBatch * 8];
    for (std::size_t i = 0; i < count; i += kBatch) {
      const std::size_t m = std::min(kBatch, count - i);
      for (std::size_t j = 0; j < m; ++j) {
        if (f32_) {
          const float f = static_cast<float>(v[i + j]);
          std::uint32_t b;
          std::memcpy(&b, &f, 4);
          if (swap_) b = __builtin_bswap32(b);
          std::memcpy(scratch + 4 * j, &b, 4);
        } else {
          std::uint64_t b;
          std::memcpy(&b, &v[i + j], 8);
          b = __builtin_bswap64(b);
          std::memcpy(scratch + 8 * j, &b, 8);
        }
      }
      put(scratch, m * (f32_ ? 4 : 8));
    }
  }

  bool f32_, swap_;
};

// Shortest round-trip text of a double ("0.1", "-3e-07", "12345.678").
inline char* format_double(char* p, char* end, double v) { return std::to_chars(p, end, v).ptr; }

class TextWriter : public PointWriter {
 public:
  explicit TextWriter(char sep) : sep_(sep) {}

 protected:
  void encode(const double* xyz, std::size_t n) override {
    char line[3 * 32 + 4];
    for (std::size_t i = 0; i < n; ++i) {
      char* p = line;
      char* end = line + sizeof line;
      p = format_double(p, end, xyz[3 * i]);
      *p++ = sep_;
      p = format_double(p, end, xyz[3 * i + 1]);
      *p++ = sep_;
      p = format_double(p, end, xyz[3 * i + 2]);
      *p++ = '\n';
      put(line, static_cast<std::size_t>(p - line));
    }
  }
  char sep_;
};

std::string count_text(std::uint64_t count) {
  if (count != PointWriter::kUnknownCount) return std::to_string(count);
  return std::string(kCountWidth, ' ');  // patched at commit()
}

// PLY: "element vertex N" then double (or float) x, y, z; binary or ASCII.
class PlyWriter : public RawWriter {
 public:
  PlyWriter(bool ascii, bool f32, bool big) : RawWriter(f32, big), ascii_(ascii), big_(big) {}

  void write_header() {
    std::string h = "ply\nformat ";
    h += ascii_ ? "ascii" : big_ ? "binary_big_endian" : "binary_little_endian";
    h += " 1.0\ncomment written by tetstream\nelement vertex ";
    count_offset_ = h.size();
    h += count_text(count_);
    const char* t = ascii_ || !f32_ ? "double" : "float";
    h += std::string("\nproperty ") + t + " x\nproperty " + t + " y\nproperty " + t + " z\nend_header\n";
    put(h.data(), h.size());
  }

 protected:
  void encode(const double* xyz, std::size_t n) override {
    if (!ascii_) return RawWriter::encode(xyz, n);
    char line[3 * 32 + 4];
    for (std::size_t i = 0; i < n; ++i) {
      char* p = line;
      char* end = line + sizeof line;
      for (int c = 0; c < 3; ++c) {
        p = format_double(p, end, xyz[3 * i + c]);
        *p++ = c < 2 ? ' ' : '\n';
      }
      put(line, static_cast<std::size_t>(p - line));
    }
  }
  void finish() override {
    if (count_ != kUnknownCount) return;
    flush();
    std::string c = std::to_string(points_);
    c.resize(kCountWidth, ' ');  // trailing blanks: PLY readers split header lines on blanks
    pwrite_at(count_offset_, c.data(), c.size());
  }

  bool ascii_, big_;
  std::size_t count_offset_ = 0;
};

// .npy v1: the header dict padded with blanks so the data starts on a 64-byte boundary.
class NpyWriter : public RawWriter {
 public:
  NpyWriter(bool f32, bool big) : RawWriter(f32, big) { descr_ = std::string(big ? ">" : "<") + (f32 ? "f4" : "f8"); }

  void write_header() {
    const std::string h = header(count_ == kUnknownCount ? std::string(kCountWidth, '9') : std::to_string(count_), 0);
    header_size_ = h.size();
    put(h.data(), h.size());
  }

 protected:
  std::string header(const std::string& count, std::size_t total) const {
    return npy_header(descr_, count + ", 3", total);
  }
  void finish() override {
    if (count_ != kUnknownCount) return;
    flush();
    const std::string h = header(std::to_string(points_), header_size_);
    pwrite_at(0, h.data(), h.size());
  }

  std::string descr_;
  std::size_t header_size_ = 0;
};

}  // namespace

std::unique_ptr<PointWriter> create_points(const std::string& path, const PointWriteOptions& options,
                                           std::uint64_t count) {
  PointFormat format = options.format;
  ScalarType type = options.type;
  FormatGuess guess;
  if (!is_std_stream(path)) guess = format_from_extension(path);
  if (format == PointFormat::kAuto) format = guess.format;
  if (type == ScalarType::kAuto && format == guess.format) type = guess.type;
  if (format == PointFormat::kAuto) {
    throw UsageError("cannot tell the output format of " + path +
                     " from its extension: name it with --format (f32, f64, ply, npy, text)");
  }
  const bool f32 = type == ScalarType::kFloat32;
  const bool big = options.byte_order == ByteOrder::kBig;
  if ((format == PointFormat::kPly || format == PointFormat::kNpy) && count == PointWriter::kUnknownCount &&
      is_std_stream(path)) {
    throw UsageError("writing PLY or npy to stdout needs the point count up front");
  }

  std::unique_ptr<PointWriter> w;
  switch (format) {
    case PointFormat::kRaw: {
      w = std::make_unique<RawWriter>(f32, big);
      w->format_name_ = std::string("raw ") + (f32 ? "f32 " : "f64 ") + (big ? "big-endian" : "little-endian");
      break;
    }
    case PointFormat::kText: {
      const bool csv = path.size() >= 4 && path.compare(path.size() - 4, 4, ".csv") == 0;
      w = std::make_unique<TextWriter>(csv ? ',' : ' ');
      w->format_name_ = "text";
      break;
    }
    case PointFormat::kPly: {
      auto ply = std::make_unique<PlyWriter>(options.ascii, f32, big);
      ply->format_name_ = options.ascii ? "ply ascii" : big ? "ply binary_big_endian" : "ply binary_little_endian";
      w = std::move(ply);
      break;
    }
    case PointFormat::kNpy: {
      auto npy = std::make_unique<NpyWriter>(f32, big);
      npy->format_name_ = std::string("npy ") + (big ? ">" : "<") + (f32 ? "f4" : "f8");
      w = std::move(npy);
      break;
    }
    case PointFormat::kLas:
    case PointFormat::kHdf5:
      throw UsageError(std::string("points cannot be written as ") + to_string(format) +
                       " (input only): write f32, f64, ply, npy or text");
    case PointFormat::kAuto:
      break;
  }
  w->count_ = count;
  w->open(path, options.buffer_bytes);
  if (auto* ply = dynamic_cast<PlyWriter*>(w.get())) ply->write_header();
  if (auto* npy = dynamic_cast<NpyWriter*>(w.get())) npy->write_header();
  return w;
}

}  // namespace tetstream::io
