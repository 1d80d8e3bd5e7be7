#include "io/tet_reader.hpp"
#include "io/output_file.hpp"

#include "core/error.hpp"
#include "io/tet_codec.hpp"

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <vector>
#include <fcntl.h>
#include <stdexcept>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

namespace tetstream::io {

namespace {
std::string frame_name(std::uint64_t k) { return "frame " + std::to_string(k) + ": "; }
}  // namespace

void TetReader::fail(std::uint64_t offset, const std::string& problem) const {
  throw InputError::at_byte(path_, offset, problem);
}

namespace {
// Standard input copied into an unnamed file in $TMPDIR (O_TMPFILE: nothing to clean
// up, whatever happens): the random-access reader needs a file to map. `cat -` reads
// the stream as it comes instead (io/tet_stream_reader.hpp).
int spool_stdin() {
  const char* env = std::getenv("TMPDIR");
  const std::string dir = env && *env ? env : "/tmp";
  const int fd = ::open(dir.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
  if (fd < 0) throw IoError(dir + ": cannot make a temporary file for standard input: " + std::strerror(errno));
  std::vector<char> buf(std::size_t(1) << 20);
  for (;;) {
    const ssize_t n = ::read(STDIN_FILENO, buf.data(), buf.size());
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw IoError(std::string("standard input: read failed: ") + std::strerror(errno));
    if (n == 0) break;
    for (ssize_t done = 0; done < n;) {
      const ssize_t w = ::write(fd, buf.data() + done, std::size_t(n - done));
      if (w < 0 && errno == EINTR) continue;
      if (w < 0) {
        const int e = errno;
        ::close(fd);
        throw IoError(dir + ": cannot spool standard input: " + std::strerror(e));
      }
      done += w;
    }
  }
  return fd;
}
}  // namespace

TetReader::TetReader(std::string path, Periodic periodic) : path_(std::move(path)) {
  fd_ = path_ == "-" ? spool_stdin() : ::open(path_.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) throw IoError(path_ + ": cannot open: " + std::strerror(errno));
  note_input_fd(fd_);
  struct stat st;
  if (::fstat(fd_, &st) != 0) {
    const int e = errno;
    ::close(fd_);
    throw IoError(path_ + ": cannot stat: " + std::strerror(e));
  }
  size_ = std::uint64_t(st.st_size);
  if (size_ > 0) {
    void* m = ::mmap(nullptr, size_, PROT_READ, MAP_PRIVATE, fd_, 0);
    if (m == MAP_FAILED) {
      const int e = errno;
      ::close(fd_);
      throw IoError(path_ + ": cannot map: " + std::strerror(e));
    }
    data_ = static_cast<const std::uint8_t*>(m);
  }
  try {
    // §3.1 preamble.
    if (size_ < kPreambleSize || std::memcmp(data_, kFileMagic.data(), kFileMagic.size()) != 0) {
      fail(0, "not a .tets container (bad magic)");
    }
    version_major_ = get_u16(data_ + 8);
    version_minor_ = get_u16(data_ + 10);
    if (!version_readable(version_major_)) {
      fail(8, "unsupported container version " + std::to_string(version_major_) + "." + std::to_string(version_minor_) +
                  " (this reader reads " + std::to_string(kVersionMajor) + ".x and " +
                  std::to_string(kVersionMajorBricks) + ".x)");
    }
    // §3.7 footer.
    if (size_ < kPreambleSize + kFooterSize) fail(size_, "truncated: no footer");
    const std::uint64_t footer_at = size_ - kFooterSize;
    if (const std::string p =
            parse_footer(std::span<const std::uint8_t, kFooterSize>(data_ + footer_at, kFooterSize), footer_);
        !p.empty()) {
      fail(footer_at, p);
    }
    // §3.6 index: it must end exactly at the footer.
    const std::uint64_t ix = footer_.index_offset;
    if (ix < kPreambleSize || ix > footer_at || footer_at - ix < kSectionHeaderSize + kSectionTrailerSize ||
        get_u64(data_ + ix + 8) != footer_at - ix - kSectionHeaderSize - kSectionTrailerSize) {
      fail(footer_at, "footer does not point at an index that ends at the footer");
    }
    const auto index =
        section_payload(ix, kTagIndex, footer_at - ix - kSectionHeaderSize - kSectionTrailerSize, "index");
    if (const std::string p = parse_index(index, sections_, frames_); !p.empty()) fail(ix + kSectionHeaderSize, p);

    // The directory: HEAD and PNTS, and no critical section this reader does not know.
    const SectionEntry* head = nullptr;
    const SectionEntry* pnts = nullptr;
    for (const auto& s : sections_) {
      if (s.offset > ix || s.length > ix - s.offset ||
          ix - s.offset - s.length < kSectionHeaderSize + kSectionTrailerSize) {
        fail(ix + kSectionHeaderSize, "directory entry for section " + tag_name(s.tag) + " lies outside the file");
      }
      if (s.tag == kTagHead && !head) {
        head = &s;
      } else if (s.tag == kTagPoints && !pnts) {
        pnts = &s;
      } else if (s.tag == kTagPeriodicBox || s.tag == kTagPeriodicOffsets) {
        if (periodic == Periodic::kRefuse) {
          fail(s.offset, "a periodic triangulation (section " + tag_name(s.tag) +
                             ", docs/periodic.md): this command does not read periodic containers yet");
        }
        if (s.tag == kTagPeriodicBox) periodic_box_ = &s;
      } else if (s.flags & kSectionCritical) {
        fail(s.offset, "unknown critical section " + tag_name(s.tag) + " (written by a newer version?)");
      }
    }
    if (!head || !pnts) fail(ix + kSectionHeaderSize, "the directory lacks the header or the points");
    const auto hp = section_payload(head->offset, kTagHead, head->length, "header");
    if (const std::string p = parse_head(hp, header_); !p.empty()) fail(head->offset + kSectionHeaderSize, p);
    header_.version_major = version_major_;
    const std::uint64_t n = header_.point_count;
    if (footer_.point_count != n) fail(footer_at, "footer and header disagree on the point count");
    const std::uint64_t rec = header_.point_record_bytes();
    if (pnts->length / rec != n || pnts->length % rec != 0 || get_u32(data_ + pnts->offset) != kTagPoints ||
        get_u64(data_ + pnts->offset + 8) != pnts->length) {
      fail(pnts->offset, "points section does not hold " + std::to_string(n) + " records");
    }
    points_offset_ = pnts->offset + kSectionHeaderSize;

    // Frames: in order, inside the file, counts adding up.
    if (frames_.size() != footer_.frame_count) fail(footer_at, "footer and index disagree on the frame count");
    std::uint64_t tets = 0, prev_end = pnts->offset + kSectionHeaderSize + pnts->length + kSectionTrailerSize;
    for (std::uint64_t k = 0; k < frames_.size(); ++k) {
      const FrameEntry& f = frames_[k];
      const std::uint64_t entry_at =
          ix + kSectionHeaderSize + 4 + sections_.size() * kSectionEntrySize + 8 + k * kFrameEntrySize;
      if (f.offset < prev_end || f.offset > ix || ix - f.offset < kSectionHeaderSize + kSectionTrailerSize ||
          f.length > ix - f.offset - kSectionHeaderSize - kSectionTrailerSize) {
        fail(entry_at, frame_name(k) + "index entry points outside the frames");
      }
      if (f.first_tet != tets || f.tet_count == 0 || f.base_label > f.max_label || f.max_label >= n) {
        fail(entry_at, frame_name(k) + "index entry is inconsistent");
      }
      tets += f.tet_count;
      prev_end = f.offset + kSectionHeaderSize + f.length + kSectionTrailerSize;
      tet_bytes_ += kSectionHeaderSize + f.length + kSectionTrailerSize;
    }
    if (tets != footer_.tet_count) fail(footer_at, "footer and index disagree on the tet count");
  } catch (...) {
    if (data_) ::munmap(const_cast<std::uint8_t*>(data_), size_);
    ::close(fd_);
    throw;
  }
}

bool TetReader::is_periodic_file(const std::string& path) {
  return path != "-" && TetReader(path, Periodic::kAccept).periodic();
}

TetReader::~TetReader() {
  if (data_) ::munmap(const_cast<std::uint8_t*>(data_), size_);
  if (fd_ >= 0) ::close(fd_);
}

std::span<const std::uint8_t> TetReader::section_payload(std::uint64_t offset, std::uint32_t tag, std::uint64_t length,
                                                         const std::string& what) const {
  if (offset > size_ || size_ - offset < kSectionHeaderSize + kSectionTrailerSize ||
      length > size_ - offset - kSectionHeaderSize - kSectionTrailerSize) {
    fail(offset, what + " section lies outside the file");
  }
  const std::uint8_t* h = data_ + offset;
  if (get_u32(h) != tag) fail(offset, what + ": expected section " + tag_name(tag) + ", found " + tag_name(get_u32(h)));
  if (get_u64(h + 8) != length) fail(offset + 8, what + ": section length differs from the index");
  const std::uint8_t* p = h + kSectionHeaderSize;
  if (crc32c(p, length) != get_u32(p + length)) fail(offset, what + ": checksum mismatch (the file is damaged)");
  return {p, length};
}

std::span<const std::uint8_t> TetReader::section(std::uint32_t tag) const {
  for (const SectionEntry& s : sections_) {
    if (s.tag == tag) return section_payload(s.offset, tag, s.length, tag_name(tag));
  }
  return {};
}

std::span<const std::uint8_t> TetReader::frame_payload(std::uint64_t k) const {
  if (k >= frames_.size()) {
    throw std::out_of_range("frame " + std::to_string(k) + " of " + std::to_string(frames_.size()));
  }
  const FrameEntry& f = frames_[k];
  return section_payload(f.offset, kTagFrame, f.length, "frame " + std::to_string(k));
}

namespace {
template <class L>
void read_frame_impl(const TetReader& r, std::uint64_t k, std::span<const std::uint8_t> payload, std::vector<L>& labels,
                     std::uint64_t offset) {
  thread_local FrameDecoder decoder;
  const FrameEntry& f = r.frames()[k];
  FrameHeader h;
  if (parse_frame_header(payload, h).empty() &&
      (h.tet_count != f.tet_count || h.base_label != f.base_label || h.max_label != f.max_label)) {
    throw InputError::at_byte(r.path(), offset, frame_name(k) + "header differs from its index entry");
  }
  try {
    decoder.decode(payload, labels);
  } catch (const FrameError& e) {
    throw InputError::at_byte(r.path(), offset + e.offset(), frame_name(k) + e.what());
  }
}
}  // namespace

void TetReader::read_frame(std::uint64_t k, std::vector<std::uint64_t>& labels) const {
  const auto p = frame_payload(k);
  read_frame_impl(*this, k, p, labels, frames_[k].offset + kSectionHeaderSize);
}

void TetReader::read_frame(std::uint64_t k, std::vector<std::uint32_t>& labels) const {
  const auto p = frame_payload(k);
  read_frame_impl(*this, k, p, labels, frames_[k].offset + kSectionHeaderSize);
}

std::span<const std::uint8_t> TetReader::point_records() const {
  return {data_ + points_offset_, header_.point_count * header_.point_record_bytes()};
}

void TetReader::read_points(std::uint64_t first, std::size_t n, double* xyz, std::uint64_t* ids) const {
  if (first > header_.point_count || n > header_.point_count - first) {
    throw std::out_of_range("points " + std::to_string(first) + "+" + std::to_string(n) + " of " +
                            std::to_string(header_.point_count));
  }
  const std::size_t rec = header_.point_record_bytes();
  const bool f32 = header_.coord_type == CoordType::kFloat32;
  const bool id32 = header_.id_width == 32;
  const std::uint8_t* p = data_ + points_offset_ + first * rec;
  for (std::size_t i = 0; i < n; ++i, p += rec) {
    if (xyz) {
      if (f32) {
        float c[3];
        std::memcpy(c, p, sizeof c);
        xyz[3 * i] = c[0], xyz[3 * i + 1] = c[1], xyz[3 * i + 2] = c[2];
      } else {
        std::memcpy(xyz + 3 * i, p, 24);
      }
    }
    if (ids) {
      const std::uint8_t* q = p + (f32 ? 12 : 24);
      if (id32) {
        std::uint32_t v;
        std::memcpy(&v, q, 4);
        ids[i] = v;
      } else {
        std::memcpy(ids + i, q, 8);
      }
    }
  }
}

void TetReader::map_to_original(std::span<std::uint64_t> labels) const {
  const std::size_t rec = header_.point_record_bytes();
  const std::uint8_t* base = data_ + points_offset_ + 3 * coord_bytes(header_.coord_type);
  const bool id32 = header_.id_width == 32;
  for (auto& l : labels) {
    if (l >= header_.point_count) throw std::out_of_range("label " + std::to_string(l) + " out of range");
    const std::uint8_t* q = base + l * rec;
    if (id32) {
      std::uint32_t v;
      std::memcpy(&v, q, 4);
      l = v;
    } else {
      std::memcpy(&l, q, 8);
    }
  }
}

namespace {
// Whole pages inside [p, p + bytes) only: a partial page at either end may hold bytes
// a caller still reads.
void release_range(const std::uint8_t* p, std::uint64_t bytes) {
  const std::uintptr_t page = std::uintptr_t(::sysconf(_SC_PAGESIZE));
  const std::uintptr_t b = std::uintptr_t(p), e = b + bytes;
  const std::uintptr_t lo = (b + page - 1) / page * page, hi = e / page * page;
  if (hi > lo) ::madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_DONTNEED);
}
}  // namespace

void TetReader::release_frame_pages(std::uint64_t k) const {
  const FrameEntry& f = frames_.at(std::size_t(k));
  release_range(data_ + f.offset, kSectionHeaderSize + std::uint64_t(f.length) + kSectionTrailerSize);
}

void TetReader::release_point_pages(std::uint64_t first, std::uint64_t n) const {
  const std::uint64_t size = header_.point_record_bytes();
  release_range(data_ + points_offset_ + first * size, n * size);
}

void TetReader::verify_points() const {
  // A slice at a time, each one's pages handed back once summed: the check reads the
  // whole section, which would otherwise stay in the resident set beside the copy a
  // caller makes next (verify at 10^7 points: 279 MB of mapped pages on top of the
  // 231 MiB of coordinates that --memory counts, 558 MB at --memory 400M).
  const auto p = point_records();
  constexpr std::size_t kSlice = std::size_t(16) << 20;
  std::uint32_t crc = 0;
  for (std::size_t at = 0; at < p.size(); at += kSlice) {
    const std::size_t n = std::min(kSlice, p.size() - at);
    crc = crc32c(p.data() + at, n, crc);
    release_range(p.data() + at, n);
  }
  if (crc != get_u32(p.data() + p.size())) {
    fail(points_offset_ - kSectionHeaderSize, "points: checksum mismatch (the file is damaged)");
  }
}

int perturbation_axis(const TetReader& reader) {
  if (reader.version_major() == kVersionMajor) return -1;
  const TetFileHeader& h = reader.header();
  int axis = 0;
  for (int k = 1; k < 3; ++k)
    if (h.bbox_max[k] - h.bbox_min[k] > h.bbox_max[axis] - h.bbox_min[axis]) axis = k;
  return axis;
}

std::uint64_t label_brick(const TetReader& reader) {
  return reader.version_major() == kVersionMajor ? 1 : brick_labels(reader.point_count());
}

}  // namespace tetstream::io
