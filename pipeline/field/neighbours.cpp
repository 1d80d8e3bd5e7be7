#include "pipeline/field/neighbours.hpp"

#include "core/error.hpp"
#include "io/npy.hpp"
#include "io/output_file.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <limits>
#include <memory>
#include <stdexcept>

namespace tetstream::pipeline {
namespace {

constexpr std::uint64_t kNone = std::numeric_limits<std::uint64_t>::max();

// An integer .npy array (int32 or int64) written front to back through a buffer: rows
// are ~15 entries, too small to be writes of their own.
template <class Index>
class IntArray {
 public:
  IntArray(const std::string& path, std::uint64_t n) : w_(path, sizeof(Index) == 4 ? "<i4" : "<i8", {n}) {
    b_.reserve(kBuffer);
  }
  void add(std::uint64_t v) {
    b_.push_back(Index(v));
    if (b_.size() == kBuffer) flush();
  }
  void add(const std::uint32_t* v, std::size_t n) {
    while (n > 0) {
      const std::size_t k = std::min(n, kBuffer - b_.size());
      b_.insert(b_.end(), v, v + k);  // below INT32_MAX when Index is int32 (needs_int64)
      v += k, n -= k;
      if (b_.size() == kBuffer) flush();
    }
  }
  void commit() {
    flush();
    w_.commit();
  }

 private:
  static constexpr std::size_t kBuffer = std::size_t(1) << 16;
  void flush() {
    w_.write(b_.data(), b_.size() * sizeof(Index));
    b_.clear();
  }
  io::NpyArrayWriter w_;
  std::vector<Index> b_;
};

// The words of a bucket's chunks, read in order through one buffer.
class ChunkReader {
 public:
  ChunkReader(int fd, const std::string& path, const std::vector<NeighbourRowsChunk>& chunks)
      : fd_(fd), path_(path), chunks_(chunks), buf_(std::size_t(1) << 18) {}
  // The next word; false at the end of the last chunk.
  bool next(std::uint32_t& w) {
    if (pos_ == end_ && !refill()) return false;
    w = buf_[pos_++];
    return true;
  }
  // Appends the next n words to out (nullptr: skips them).
  void take(std::uint64_t n, std::vector<std::uint32_t>* out) {
    while (n > 0) {
      if (pos_ == end_ && !refill()) throw IoError(path_ + ": a neighbour row is cut short");
      const std::size_t k = std::size_t(std::min<std::uint64_t>(n, end_ - pos_));
      if (out) out->insert(out->end(), buf_.begin() + std::ptrdiff_t(pos_), buf_.begin() + std::ptrdiff_t(pos_ + k));
      pos_ += k, n -= k;
    }
  }

 private:
  bool refill() {
    while (chunk_ < chunks_.size() && read_in_chunk_ == chunks_[chunk_].words) ++chunk_, read_in_chunk_ = 0;
    if (chunk_ == chunks_.size()) return false;
    const NeighbourRowsChunk& c = chunks_[chunk_];
    const std::uint64_t k = std::min<std::uint64_t>(buf_.size(), c.words - read_in_chunk_);
    if (!io::pread_exactly(fd_, buf_.data(), std::size_t(k) * sizeof(std::uint32_t),
                           (c.offset + read_in_chunk_) * sizeof(std::uint32_t)))
      throw IoError(path_ + ": read failed");
    read_in_chunk_ += k;
    pos_ = 0, end_ = std::size_t(k);
    return true;
  }
  int fd_;
  const std::string& path_;
  const std::vector<NeighbourRowsChunk>& chunks_;
  std::vector<std::uint32_t> buf_;
  std::size_t chunk_ = 0, pos_ = 0, end_ = 0;
  std::uint64_t read_in_chunk_ = 0;
};

// Writes the rows of data (whole rows [original, degree, neighbours...], originals in
// [lo, hi)) in original order; at: entries written so far.
template <class Index>
void write_rows(const std::vector<std::uint32_t>& data, std::uint64_t lo, std::uint64_t hi,
                std::vector<std::uint64_t>& pos, IntArray<Index>& offsets, IntArray<Index>& indices, std::uint64_t& at,
                std::uint64_t& rows) {
  pos.assign(std::size_t(hi - lo), kNone);
  for (std::size_t i = 0; i < data.size(); i += 2 + std::size_t(data[i + 1])) {
    std::uint64_t& p = pos[std::size_t(data[i] - lo)];
    if (p != kNone) throw std::logic_error("field: two neighbour rows for original index " + std::to_string(data[i]));
    p = i;
  }
  for (const std::uint64_t p : pos) {
    if (p == kNone) continue;  // a duplicate `run` merged: no row
    const std::uint64_t degree = data[std::size_t(p) + 1];
    indices.add(data.data() + p + 2, std::size_t(degree));
    at += degree;
    offsets.add(at);
    ++rows;
  }
}

}  // namespace

NeighbourRows::NeighbourRows(std::uint64_t original_end, std::uint64_t point_count, std::uint64_t entries_bound,
                             std::uint64_t memory_bytes, std::string scratch)
    : original_end_(std::max<std::uint64_t>(original_end, 1)), point_count_(point_count), scratch_(std::move(scratch)) {
  // Pass 1 buffers at most half the share: the window and the batch are live beside
  // it (their own accounting misses the entries pending for unretired labels). One
  // bucket when the rows (2 header words a row, 4 bytes a word) fit that half and, with
  // the placement array (8 bytes an original index), the whole share once pass 1 has
  // freed its structures; else buckets of about half the share each, so that one
  // bucket and its placement array fit when it is written, skew included.
  const std::uint64_t budget = std::max<std::uint64_t>(memory_bytes, std::uint64_t(1) << 18);
  const std::uint64_t pass1 = budget / 2;
  const std::uint64_t rows_bytes = sizeof(std::uint32_t) * (2 * point_count + entries_bound);
  const std::uint64_t placement_bytes = sizeof(std::uint64_t) * original_end_;
  std::uint64_t b = 1;
  if (rows_bytes > pass1 || rows_bytes + placement_bytes > budget)
    b = (rows_bytes + placement_bytes + pass1 - 1) / pass1;
  b = std::min(b, original_end_);
  width_ = (original_end_ + b - 1) / b;
  b = (original_end_ + width_ - 1) / width_;
  // Rows land in buckets at random (input order is not spatial order): the buffers
  // split the half evenly.
  half_words_ = pass1 / sizeof(std::uint32_t);
  words_per_bucket_ = std::max<std::uint64_t>(half_words_ / b, 1 << 12);
  buffers_.resize(std::size_t(b));
  chunks_.resize(std::size_t(b));
  bucket_words_.assign(std::size_t(b), 0);
}

NeighbourRows::~NeighbourRows() {
  if (file_) {
    file_.reset();
    remove_file(scratch_);
  }
}

void NeighbourRows::add(std::uint64_t original, std::span<const std::uint32_t> neighbours) {
  const std::size_t b = std::size_t(original / width_);
  std::vector<std::uint32_t>& buf = buffers_.at(b);
  const std::uint64_t row = 2 + neighbours.size();
  if (!buf.empty() && buf.size() + row > words_per_bucket_) spill(b);
  // Reserved once: a doubling vector would hold one and a half buffers while it grows.
  if (buf.capacity() == 0) buf.reserve(std::size_t(words_per_bucket_));
  buf.push_back(std::uint32_t(original));  // below 2^32: field.cpp refuses more points
  buf.push_back(std::uint32_t(neighbours.size()));
  buf.insert(buf.end(), neighbours.begin(), neighbours.end());
  bucket_words_[b] += row;
  entries_ += neighbours.size();
  ++rows_;
}

void NeighbourRows::spill(std::size_t b) {
  std::vector<std::uint32_t>& buf = buffers_[b];
  if (buf.empty()) return;
  if (!file_) file_ = std::make_unique<BinaryFile>(scratch_, "wb");
  file_->write(buf.data(), sizeof(std::uint32_t), buf.size());
  chunks_[b].push_back({file_words_, buf.size()});
  file_words_ += buf.size();
  buf.clear();
  spilled_ = true;
}

void NeighbourRows::load(std::size_t b, std::uint64_t lo, std::uint64_t hi, std::vector<std::uint32_t>& out) {
  out.clear();
  const int fd = ::open(scratch_.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw IoError(scratch_ + ": cannot open");
  try {
    ChunkReader in(fd, scratch_, chunks_[b]);
    std::uint32_t original = 0, degree = 0;
    while (in.next(original)) {
      if (!in.next(degree)) throw IoError(scratch_ + ": a neighbour row is cut short");
      const bool keep = original >= lo && original < hi;
      if (keep) out.push_back(original), out.push_back(degree);
      in.take(degree, keep ? &out : nullptr);
    }
  } catch (...) {
    ::close(fd);
    throw;
  }
  ::close(fd);
}

bool NeighbourRows::needs_int64() const {
  constexpr std::uint64_t kInt32Max = std::uint64_t(std::numeric_limits<std::int32_t>::max());
  return entries_ > kInt32Max || original_end_ - 1 > kInt32Max;
}

void NeighbourRows::write(const std::string& offsets_path, const std::string& indices_path, bool wide) {
  if (rows_ != point_count_)
    throw std::logic_error("field: " + std::to_string(rows_) + " neighbour rows, expected " +
                           std::to_string(point_count_));
  if (wide) return write_as<std::int64_t>(offsets_path, indices_path);
  if (needs_int64()) throw std::logic_error("field: the neighbour arrays do not fit int32");
  write_as<std::int32_t>(offsets_path, indices_path);
}

template <class Index>
void NeighbourRows::write_as(const std::string& offsets_path, const std::string& indices_path) {
  IntArray<Index> offsets(offsets_path, point_count_ + 1), indices(indices_path, entries_);
  offsets.add(0);
  std::uint64_t at = 0, rows = 0;
  std::vector<std::uint64_t> pos;
  std::vector<std::uint32_t> data;
  if (!spilled_) {
    // Everything is in memory: each bucket in place.
    for (std::size_t b = 0; b < buffers_.size(); ++b) {
      const std::uint64_t lo = b * width_, hi = std::min(original_end_, lo + width_);
      write_rows(buffers_[b], lo, hi, pos, offsets, indices, at, rows);
      std::vector<std::uint32_t>().swap(buffers_[b]);
    }
  } else {
    // Every row to the file, the buffers freed; then a bucket at a time, in parts of
    // its original range when it came out larger than planned (a skewed degree
    // distribution): each part rereads the bucket's chunks and keeps its own rows.
    for (std::size_t b = 0; b < buffers_.size(); ++b) {
      spill(b);
      std::vector<std::uint32_t>().swap(buffers_[b]);
    }
    file_->close();
    const std::uint64_t half = std::max<std::uint64_t>(half_words_, 1);
    for (std::size_t b = 0; b < buffers_.size(); ++b) {
      const std::uint64_t lo = b * width_, hi = std::min(original_end_, lo + width_);
      // Its rows' words and its placement array (two words an original index).
      const std::uint64_t parts = std::max<std::uint64_t>(1, (bucket_words_[b] + 2 * (hi - lo) + half - 1) / half);
      const std::uint64_t step = (hi - lo + parts - 1) / parts;
      for (std::uint64_t p = lo; p < hi; p += step) {
        load(b, p, std::min(hi, p + step), data);
        write_rows(data, p, std::min(hi, p + step), pos, offsets, indices, at, rows);
      }
    }
  }
  if (rows != point_count_ || at != entries_)
    throw std::logic_error("field: " + std::to_string(rows) + " neighbour rows written, expected " +
                           std::to_string(point_count_));
  offsets.commit();
  indices.commit();
}

}  // namespace tetstream::pipeline
