#include "io/tet_writer.hpp"

#include "core/error.hpp"
#include "io/output_file.hpp"

#include <fcntl.h>
#include <omp.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <exception>
#include <stdexcept>

namespace tetstream::io {

namespace {

std::array<std::uint8_t, kPreambleSize> preamble(std::uint16_t major) {
  std::array<std::uint8_t, kPreambleSize> b{};
  std::copy(kFileMagic.begin(), kFileMagic.end(), b.begin());
  put_u16(b.data() + 8, major);
  put_u16(b.data() + 10, kVersionMinor);
  put_u32(b.data() + 12, 0);
  return b;
}

}  // namespace

std::vector<std::uint8_t> leading_bytes(const TetFileHeader& h) {
  const auto pre = preamble(h.version_major);
  const std::vector<std::uint8_t> head = serialize_head(h);
  const auto hh = section_header(kTagHead, kSectionCritical, head.size());
  const auto ph = section_header(kTagPoints, kSectionCritical, h.point_count * h.point_record_bytes());
  std::vector<std::uint8_t> b(pre.size() + hh.size() + head.size() + kSectionTrailerSize + ph.size());
  std::uint8_t* p = b.data();
  p = std::copy(pre.begin(), pre.end(), p);
  p = std::copy(hh.begin(), hh.end(), p);
  p = std::copy(head.begin(), head.end(), p);
  put_u32(p, crc32c(head.data(), head.size()));
  std::copy(ph.begin(), ph.end(), p + kSectionTrailerSize);
  return b;
}

namespace {

void validate_options(const TetWriterOptions& o) {
  if (o.frame_tets == 0 || o.frame_tets > kMaxFrameTets) {
    throw std::invalid_argument("frame size must be 1.." + std::to_string(kMaxFrameTets) + " tets");
  }
}

// Reads the TETF section at `at` of `name` (read(offset, data, n) reads its bytes),
// which must end by `end`: its payload and CRC into `section` (resized to hold them),
// its frame header into `fh`. Checks the tag, the length, the CRC and the frame
// header: InputError naming the file and the offset otherwise. Returns the payload's
// length.
template <class Read>
std::uint64_t read_frame_section(Read&& read, const std::string& name, std::uint64_t at, std::uint64_t end,
                                 std::size_t frame, std::vector<std::uint8_t>& section, FrameHeader& fh) {
  std::uint8_t sh[kSectionHeaderSize];
  if (end - at < kSectionHeaderSize + kSectionTrailerSize) throw InputError::at_byte(name, at, "ends inside a section");
  read(at, sh, sizeof sh);
  const std::uint64_t len = get_u64(sh + 8);
  if (get_u32(sh) != kTagFrame || len > end - at - kSectionHeaderSize - kSectionTrailerSize)
    throw InputError::at_byte(name, at, "not a complete frame");
  section.resize(len + kSectionTrailerSize);
  read(at + kSectionHeaderSize, section.data(), section.size());
  if (crc32c(section.data(), len) != get_u32(section.data() + len))
    throw InputError::at_byte(name, at, "frame " + std::to_string(frame) + ": checksum mismatch");
  if (const std::string problem = parse_frame_header({section.data(), len}, fh); !problem.empty())
    throw InputError::at_byte(name, at + kSectionHeaderSize, problem);
  return len;
}

}  // namespace

TetWriter::TetWriter(std::string path, TetFileHeader header, TetWriterOptions options)
    : path_(std::move(path)), header_(std::move(header)), options_(options) {
  header_.resolve_and_validate();
  validate_options(options_);
  out_ = path_ == "-" ? OutputFile::to_stdout(options_.buffer_bytes)
                      : std::make_unique<OutputFile>(path_, options_.buffer_bytes, options_.claim);
  out_->keep_on_failure(options_.keep_partial);
  const std::vector<std::uint8_t> lead = leading_bytes(header_);
  out_->write(lead.data(), lead.size());
  const std::uint64_t head_len = lead.size() - kPreambleSize - 2 * kSectionHeaderSize - kSectionTrailerSize;
  sections_.push_back({kTagHead, kSectionCritical, kPreambleSize, head_len});
  const std::uint64_t pnts_at = lead.size() - kSectionHeaderSize;
  const std::uint64_t pnts_len = header_.point_count * header_.point_record_bytes();
  sections_.push_back({kTagPoints, kSectionCritical, pnts_at, pnts_len});
  points_end_ = pnts_at + kSectionHeaderSize + pnts_len + kSectionTrailerSize;
}

TetWriter::TetWriter(Resume, std::string path, TetFileHeader header, TetWriterOptions options)
    : path_(std::move(path)), header_(std::move(header)), options_(options) {}

std::unique_ptr<TetWriter> TetWriter::resume(std::string path, TetFileHeader header, std::uint64_t committed,
                                             TetWriterOptions options) {
  header.resolve_and_validate();
  validate_options(options);
  std::unique_ptr<TetWriter> w(new TetWriter(Resume{}, std::move(path), std::move(header), options));
  const std::vector<std::uint8_t> lead = leading_bytes(w->header_);
  const std::uint64_t pnts_at = lead.size() - kSectionHeaderSize;
  const std::uint64_t pnts_len = w->header_.point_count * w->header_.point_record_bytes();
  w->sections_.push_back(
      {kTagHead, kSectionCritical, kPreambleSize, pnts_at - kPreambleSize - kSectionHeaderSize - kSectionTrailerSize});
  w->sections_.push_back({kTagPoints, kSectionCritical, pnts_at, pnts_len});
  w->points_end_ = pnts_at + kSectionHeaderSize + pnts_len + kSectionTrailerSize;
  const std::string partial = w->path_ + ".partial";
  if (committed < w->points_end_) {
    throw InputError::at_byte(partial, committed, "cannot resume before the points are complete");
  }
  w->out_ = OutputFile::reopen(w->path_, committed, options.buffer_bytes, options.claim);
  // Before the checks below: a resume that fails them must not delete the job's file.
  w->out_->keep_on_failure(options.keep_partial);
  OutputFile& f = *w->out_;

  std::vector<std::uint8_t> have(lead.size());
  f.read_at(0, have.data(), have.size());
  if (have != lead) throw InputError::at_byte(partial, 0, "header differs from the resumed job's");
  w->points_ = w->header_.point_count;
  // The committed points are trusted only against their CRC: a flipped coordinate
  // would otherwise end in a container whose CRC was computed over other bytes.
  if (options.points_crc) {
    std::uint8_t stored[4];
    f.read_at(pnts_at + kSectionHeaderSize + pnts_len, stored, 4);
    if (*options.points_crc != get_u32(stored))
      throw InputError::at_byte(partial, pnts_at + kSectionHeaderSize + pnts_len, "points: checksum mismatch");
    w->points_crc_ = *options.points_crc;
  } else {
    std::vector<std::uint8_t> chunk(std::size_t(1) << 20);
    std::uint32_t crc = 0;
    const std::uint64_t begin = pnts_at + kSectionHeaderSize;
    for (std::uint64_t at = begin; at < begin + pnts_len;) {
      const std::size_t n = std::size_t(std::min<std::uint64_t>(chunk.size(), begin + pnts_len - at));
      f.read_at(at, chunk.data(), n);
      crc = crc32c(chunk.data(), n, crc);
      at += n;
    }
    std::uint8_t stored[4];
    f.read_at(begin + pnts_len, stored, 4);
    if (crc != get_u32(stored)) throw InputError::at_byte(partial, begin, "points: checksum mismatch");
    w->points_crc_ = crc;
  }

  w->rebuild_frame_index(w->points_end_, committed);
  return w;
}

std::unique_ptr<TetWriter> TetWriter::resume_fragment(std::string path, TetFileHeader header, std::uint64_t committed,
                                                      TetWriterOptions options) {
  header.resolve_and_validate();
  validate_options(options);
  std::unique_ptr<TetWriter> w(new TetWriter(Resume{}, std::move(path), std::move(header), options));
  w->fragment_ = true;
  w->points_ = w->header_.point_count;
  w->out_ = OutputFile::reopen(w->path_, committed, options.buffer_bytes, options.claim);
  w->out_->keep_on_failure(options.keep_partial);
  w->rebuild_frame_index(0, committed);
  return w;
}

void TetWriter::rebuild_frame_index(std::uint64_t from, std::uint64_t committed) {
  // The frames between the points (or a fragment's start) and the checkpoint, each
  // checked, as this writer's.
  const std::string partial = path_ + ".partial";
  std::vector<std::uint8_t> payload;
  auto read = [this](std::uint64_t offset, void* data, std::size_t n) { out_->read_at(offset, data, n); };
  for (std::uint64_t at = from; at < committed;) {
    if (frames_.empty() && !fragment_ && (at = skip_leading_section(at, committed)) == committed) break;
    FrameHeader fh;
    const std::uint64_t len =
        read_frame_section(read, partial + " (before the checkpoint)", at, committed, frames_.size(), payload, fh);
    frames_.push_back({at, tets_, fh.tet_count, std::uint32_t(len), fh.base_label, fh.max_label});
    tets_ += fh.tet_count;
    at += kSectionHeaderSize + len + kSectionTrailerSize;
  }
}

std::uint64_t TetWriter::skip_leading_section(std::uint64_t at, std::uint64_t committed) {
  // A section the caller added between the points and the first frame (a periodic
  // container's PBOX, docs/periodic.md): checked and kept in the index, as written.
  if (at == committed) return at;
  const std::string partial = path_ + ".partial";
  std::uint8_t sh[kSectionHeaderSize];
  if (committed - at < kSectionHeaderSize + kSectionTrailerSize)
    throw InputError::at_byte(partial, at, "ends inside a section");
  out_->read_at(at, sh, sizeof sh);
  const std::uint32_t tag = get_u32(sh);
  const std::uint64_t len = get_u64(sh + 8);
  if (tag == kTagFrame) return at;
  if (tag == kTagHead || tag == kTagPoints || tag == kTagIndex ||
      len > committed - at - kSectionHeaderSize - kSectionTrailerSize)
    throw InputError::at_byte(partial, at, "not a complete section before the frames");
  std::vector<std::uint8_t> payload(len + kSectionTrailerSize);
  out_->read_at(at + kSectionHeaderSize, payload.data(), payload.size());
  if (crc32c(payload.data(), len) != get_u32(payload.data() + len))
    throw InputError::at_byte(partial, at, "section before the frames: checksum mismatch");
  sections_.push_back({tag, kSectionCritical, at, len});
  return skip_leading_section(at + kSectionHeaderSize + len + kSectionTrailerSize, committed);
}

std::unique_ptr<TetWriter> TetWriter::fragment(std::string path, TetFileHeader header, TetWriterOptions options) {
  header.resolve_and_validate();
  validate_options(options);
  std::unique_ptr<TetWriter> w(new TetWriter(Resume{}, std::move(path), std::move(header), options));
  w->fragment_ = true;
  w->points_ = w->header_.point_count;  // the container's, not this file's
  w->out_ = std::make_unique<OutputFile>(w->path_, options.buffer_bytes, options.claim);
  w->out_->keep_on_failure(options.keep_partial);
  return w;
}

namespace {

// A file opened without following a link, closed on scope exit; a regular file only.
struct OpenedRegular {
  int fd = -1;
  struct stat st {};
  OpenedRegular(const std::string& path, int flags, const char* what) {
    fd = ::open(path.c_str(), flags | O_NOFOLLOW | O_CLOEXEC);
    if (fd < 0) throw IoError(path + ": cannot open " + what + ": " + std::strerror(errno));
    if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
      ::close(fd);
      throw IoError(path + ": not a regular file");
    }
  }
  ~OpenedRegular() { ::close(fd); }
  OpenedRegular(const OpenedRegular&) = delete;
  OpenedRegular& operator=(const OpenedRegular&) = delete;
};

// Walks the frames of a fragment file (it was made by this job, in its own directory:
// a regular file, not through a link), checking each one's section, CRC and header;
// `on_frame(len, section, header)` sees each, `section` holding its payload and CRC.
template <class OnFrame>
void for_each_fragment_frame(const std::string& path, std::uint64_t point_count, OnFrame&& on_frame) {
  const OpenedRegular file(path, O_RDONLY, "a fragment");
  const std::uint64_t end = std::uint64_t(file.st.st_size);
  auto read = [&](std::uint64_t offset, void* data, std::size_t n) {
    if (!pread_exactly(file.fd, data, n, offset)) throw IoError(path + ": read failed: " + std::strerror(errno));
  };
  std::vector<std::uint8_t> section;
  std::size_t frame = 0;
  for (std::uint64_t at = 0; at < end; ++frame) {
    FrameHeader fh;
    const std::uint64_t len = read_frame_section(read, path, at, end, frame, section, fh);
    if (fh.max_label >= point_count)
      throw InputError::at_byte(path, at, "label " + std::to_string(fh.max_label) + " is not below the point count");
    on_frame(len, section, fh);
    at += kSectionHeaderSize + len + kSectionTrailerSize;
  }
}

}  // namespace

std::vector<FrameEntry> place_fragment(const std::string& fragment, const std::string& container_partial,
                                       std::uint64_t at, std::uint64_t point_count,
                                       std::pair<std::uint64_t, std::uint64_t> container_file) {
  OutputPart out(container_partial, container_file);
  std::vector<FrameEntry> placed;
  std::uint64_t tets = 0, offset = at;
  for_each_fragment_frame(
      fragment, point_count, [&](std::uint64_t len, const std::vector<std::uint8_t>& section, const FrameHeader& fh) {
        placed.push_back({offset, tets, fh.tet_count, std::uint32_t(len), fh.base_label, fh.max_label});
        // The bytes the container's own writer would write here.
        const auto h = section_header(kTagFrame, kSectionCritical, len);
        out.write_at(h.data(), h.size(), offset);
        out.write_at(section.data(), section.size(), offset + h.size());
        offset += h.size() + section.size();
        tets += fh.tet_count;
      });
  out.sync();
  return placed;
}

void TetWriter::adopt_placed_frames(std::span<const FrameEntry> frames, std::uint64_t bytes) {
  if (finished_ || fragment_) throw std::logic_error("TetWriter: adopt_placed_frames to a fragment or after finish");
  if (points_ != header_.point_count) throw std::logic_error("TetWriter: frames before all points");
  out_->flush();
  const std::uint64_t from = out_->offset();
  std::uint64_t expected = from;
  for (const FrameEntry& f : frames) {
    if (f.offset != expected || f.max_label >= header_.point_count)
      throw std::logic_error("TetWriter: placed frames out of order or out of range");
    frames_.push_back({f.offset, tets_, f.tet_count, f.length, f.base_label, f.max_label});
    tets_ += f.tet_count;
    expected += kSectionHeaderSize + f.length + kSectionTrailerSize;
  }
  if (expected != from + bytes) throw std::logic_error("TetWriter: placed frames do not fill the bytes given");
  out_->skip(bytes);
}

TetWriter::~TetWriter() = default;  // out_'s destructor removes the partial file unless finished or kept

std::uint64_t TetWriter::bytes_written() const { return out_ ? out_->offset() : 0; }

std::uint64_t TetWriter::tet_bytes() const {
  std::uint64_t bytes = 0;
  for (const FrameEntry& f : frames_) bytes += kSectionHeaderSize + f.length + kSectionTrailerSize;
  return bytes;
}

void TetWriter::write_section_start(std::uint32_t tag, std::uint64_t length) {
  const auto h = section_header(tag, kSectionCritical, length);
  out_->write(h.data(), h.size());
}

template <class F>
void TetWriter::add_points_impl(const F* xyz, const std::uint64_t* ids, std::size_t n) {
  if (finished_) throw std::logic_error("TetWriter: add_points after finish");
  if (n > header_.point_count - points_) {
    throw std::logic_error("TetWriter: more points than the header's " + std::to_string(header_.point_count));
  }
  const std::size_t cb = coord_bytes(header_.coord_type), ib = header_.id_width / 8;
  const std::size_t rec = 3 * cb + ib;
  // Chunks of at most 1 MiB that fit the write buffer (a small options.buffer_bytes
  // must not make reserve() grow it); the bytes do not depend on the chunk size.
  const std::size_t chunk = std::max<std::size_t>(1, std::min(std::size_t(1) << 20, out_->buffer_bytes()) / rec);
  const std::uint64_t id_limit = std::max(header_.input_count, header_.point_count);
  for (std::size_t first = 0; first < n; first += chunk) {
    const std::size_t k = std::min(chunk, n - first);
    char* p = out_->reserve(k * rec);
    char* const start = p;
    for (std::size_t i = first; i < first + k; ++i) {
      const std::uint64_t id = ids ? ids[i] : points_ + i;
      for (int c = 0; c < 3; ++c) {
        // The coordinate as stored must lie in the header's bounding box.
        double v = double(xyz[3 * i + c]);
        if (header_.coord_type == CoordType::kFloat32) {
          const float f = float(v);
          std::memcpy(p, &f, 4);
          v = f;
        } else {
          std::memcpy(p, &v, 8);
        }
        if (!(v >= header_.bbox_min[c] && v <= header_.bbox_max[c])) {
          throw std::invalid_argument("TetWriter: point " + std::to_string(points_ + i) +
                                      " lies outside the header's bounding box");
        }
        p += cb;
      }
      if (id >= id_limit) {
        throw std::invalid_argument("TetWriter: original index " + std::to_string(id) + " of point " +
                                    std::to_string(points_ + i) + " out of range");
      }
      if (ib == 4) {
        const std::uint32_t v = std::uint32_t(id);
        std::memcpy(p, &v, 4);
      } else {
        std::memcpy(p, &id, 8);
      }
      p += ib;
    }
    points_crc_ = crc32c(start, k * rec, points_crc_);
    out_->advance(k * rec);
  }
  points_ += n;
  if (points_ == header_.point_count) {
    std::uint8_t crc[4];
    put_u32(crc, points_crc_);
    out_->write(crc, 4);
  }
}

void TetWriter::add_points(const double* xyz, const std::uint64_t* ids, std::size_t n) { add_points_impl(xyz, ids, n); }
void TetWriter::add_points(const float* xyz, const std::uint64_t* ids, std::size_t n) { add_points_impl(xyz, ids, n); }

void TetWriter::add_frame(const EncodedFrame& frame) {
  if (finished_) throw std::logic_error("TetWriter: add_frame after finish");
  if (points_ != header_.point_count) {
    throw std::logic_error("TetWriter: tets before all " + std::to_string(header_.point_count) + " points");
  }
  if (frame.max_label >= header_.point_count) {
    throw std::invalid_argument("TetWriter: label " + std::to_string(frame.max_label) +
                                " is not below the point count " + std::to_string(header_.point_count));
  }
  const std::uint64_t at = out_->offset();
  write_section_start(kTagFrame, frame.payload.size());
  out_->write(frame.payload.data(), frame.payload.size());
  std::uint8_t crc[4];
  put_u32(crc, frame.crc);
  out_->write(crc, 4);
  frames_.push_back(
      {at, tets_, frame.tet_count, std::uint32_t(frame.payload.size()), frame.base_label, frame.max_label});
  tets_ += frame.tet_count;
}

template <class L>
void TetWriter::add_tets_impl(std::span<const std::span<const L>> batches) {
  // Every frame of every batch, in order: each batch is cut as it alone would be.
  std::vector<std::span<const L>> pieces;
  for (std::span<const L> labels : batches) {
    if (labels.size() % 4 != 0) throw std::invalid_argument("TetWriter: tet labels must come 4 per tet");
    const std::vector<std::size_t> bounds = frame_boundaries(labels.size() / 4, options_.frame_tets);
    for (std::size_t f = 0; f + 1 < bounds.size(); ++f)
      pieces.push_back(labels.subspan(4 * bounds[f], 4 * (bounds[f + 1] - bounds[f])));
  }
  const std::size_t frames = pieces.size();
  if (frames == 0) return;
  const int threads =
      int(std::min<std::size_t>(frames, options_.threads > 0 ? options_.threads : omp_get_max_threads()));
  while (encoders_.size() < std::size_t(threads))
    encoders_.push_back(std::make_unique<FrameEncoder>(options_.zstd_level));
  batch_.resize(std::max<std::size_t>(batch_.size(), std::size_t(threads)));
  // In waves of `threads` frames, so memory stays bounded whatever the batch size.
  for (std::size_t wave = 0; wave < frames; wave += threads) {
    const std::size_t count = std::min<std::size_t>(threads, frames - wave);
    std::exception_ptr error;
#pragma omp parallel for num_threads(threads) schedule(static, 1) if (count > 1)
    for (std::size_t i = 0; i < count; ++i) {
      try {
        encoders_[omp_get_thread_num()]->encode(pieces[wave + i], batch_[i]);
      } catch (...) {
#pragma omp critical(tetstream_writer_error)
        if (!error) error = std::current_exception();
      }
    }
    if (error) std::rethrow_exception(error);
    for (std::size_t i = 0; i < count; ++i) add_frame(batch_[i]);
  }
}

void TetWriter::add_tets(std::span<const std::uint32_t> labels) {
  add_tets_impl(std::span<const std::span<const std::uint32_t>>(&labels, 1));
}
void TetWriter::add_tets(std::span<const std::uint64_t> labels) {
  add_tets_impl(std::span<const std::span<const std::uint64_t>>(&labels, 1));
}
void TetWriter::add_tets(std::span<const std::span<const std::uint64_t>> batches) { add_tets_impl(batches); }

std::uint64_t TetWriter::checkpoint() {
  if (finished_) throw std::logic_error("TetWriter: checkpoint after finish");
  if (options_.sync) {
    out_->sync();
  } else {
    out_->flush();
  }
  return out_->offset();
}

void TetWriter::add_section(std::uint32_t tag, std::span<const std::uint8_t> payload) {
  if (finished_ || fragment_) throw std::logic_error("TetWriter: add_section after finish or in a fragment");
  if (points_ != header_.point_count) throw std::logic_error("TetWriter: add_section before the points");
  if (tag == kTagHead || tag == kTagPoints || tag == kTagFrame || tag == kTagIndex) {
    throw std::invalid_argument("TetWriter: add_section of a section the writer writes itself");
  }
  const std::uint64_t at = out_->offset();
  write_section_start(tag, payload.size());
  out_->write(payload.data(), payload.size());
  std::uint8_t crc[4];
  put_u32(crc, crc32c(payload.data(), payload.size()));
  out_->write(crc, 4);
  sections_.push_back({tag, kSectionCritical, at, payload.size()});
}

void TetWriter::discard() {
  if (finished_) throw std::logic_error("TetWriter: discard after finish");
  out_->discard();
  finished_ = true;
}

void TetWriter::finish() {
  if (finished_) throw std::logic_error("TetWriter: finish twice");
  if (fragment_) {  // frames only: the container that appends them has the index
    out_->commit(options_.sync);
    finished_ = true;
    return;
  }
  if (points_ != header_.point_count) {
    throw std::logic_error("TetWriter: finish with " + std::to_string(points_) + " of " +
                           std::to_string(header_.point_count) + " points");
  }
  const std::uint64_t index_at = out_->offset();
  const std::vector<std::uint8_t> index = serialize_index(sections_, frames_);
  write_section_start(kTagIndex, index.size());
  out_->write(index.data(), index.size());
  std::uint8_t crc[4];
  put_u32(crc, crc32c(index.data(), index.size()));
  out_->write(crc, 4);
  const auto footer = serialize_footer({index_at, tets_, frames_.size(), header_.point_count});
  out_->write(footer.data(), footer.size());
  out_->commit(options_.sync);
  finished_ = true;
}

}  // namespace tetstream::io
