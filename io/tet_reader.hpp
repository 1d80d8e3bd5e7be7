#pragma once
// Reads a .tets container (docs/format.md): header, frame by frame, points by label.
//
//   io::TetReader r("out.tets");                 // checks preamble, footer, index, header
//   std::vector<std::uint64_t> tets;
//   for (std::uint64_t k = 0; k < r.frame_count(); ++k) {
//     r.read_frame(k, tets);                     // 4 labels per tet, stored order
//     r.map_to_original(tets);                   // optional: labels -> original indices
//   }
//   r.read_points(first, n, xyz, ids);           // coordinates by label
//
// The file is memory-mapped read-only: memory is the decoded frame plus whatever pages
// the kernel keeps cached. Every problem with the file (truncated, damaged, wrong
// version, not a container) is an InputError "FILE: byte OFFSET: frame K: PROBLEM".
// Checks: the footer, index and header when opening; a frame's CRC32C, zstd checksums
// and codec rules when it is read; the points' CRC32C only in verify_points() (it reads
// them all).
//
// Thread-safety: after construction every member is const and may be called from
// several threads at once (each thread decodes with its own thread_local decoder).
#include "io/tet_container.hpp"

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace tetstream::io {

class TetReader {
 public:
  // Whether the caller reads periodic triangulations (docs/periodic.md): their tets
  // carry vertex offsets that a reader of plain tets would silently drop, so a
  // periodic file is refused (one line naming the file and the section) unless the
  // caller says it handles them.
  enum class Periodic { kRefuse, kAccept };
  // PATH "-": standard input, copied first into an unnamed temporary file.
  explicit TetReader(std::string path, Periodic periodic = Periodic::kRefuse);
  ~TetReader();
  TetReader(const TetReader&) = delete;
  TetReader& operator=(const TetReader&) = delete;

  const std::string& path() const { return path_; }
  const TetFileHeader& header() const { return header_; }
  std::uint16_t version_major() const { return version_major_; }
  std::uint16_t version_minor() const { return version_minor_; }
  std::uint64_t file_bytes() const { return size_; }
  std::uint64_t point_count() const { return header_.point_count; }
  std::uint64_t tet_count() const { return footer_.tet_count; }
  std::uint64_t frame_count() const { return frames_.size(); }
  const std::vector<FrameEntry>& frames() const { return frames_; }
  const std::vector<SectionEntry>& sections() const { return sections_; }
  // A periodic container (PBOX present; only when opened with Periodic::kAccept).
  bool periodic() const { return periodic_box_ != nullptr; }
  // Whether the container at PATH is periodic (false for "-": a stream is not opened
  // twice). Throws InputError as the constructor does.
  static bool is_periodic_file(const std::string& path);
  // The CRC-checked payload of the first section of `tag` in the directory; empty
  // when there is none.
  std::span<const std::uint8_t> section(std::uint32_t tag) const;
  // Bytes of all TETF sections (headers and trailers included): the cost of the tets.
  std::uint64_t tet_bytes() const { return tet_bytes_; }

  // Decodes frame k (0 <= k < frame_count()) into labels, 4 per tet, in stored order.
  // The 32-bit form throws InputError if the file's labels do not fit.
  void read_frame(std::uint64_t k, std::vector<std::uint64_t>& labels) const;
  void read_frame(std::uint64_t k, std::vector<std::uint32_t>& labels) const;

  // Points with labels first .. first+n-1: coordinates (3 per point, converted to
  // double) and original indices. Either output may be null.
  void read_points(std::uint64_t first, std::size_t n, double* xyz, std::uint64_t* ids) const;
  // Replaces each label by its point's original index.
  void map_to_original(std::span<std::uint64_t> labels) const;
  // Reads every point and checks PNTS's CRC32C (handing the pages back as it goes);
  // InputError if it does not match.
  void verify_points() const;
  // The raw PNTS records (format.md §3.4), for bulk copies.
  std::span<const std::uint8_t> point_records() const;
  // Hands the mapped pages of frame k, or of the points [first, first + n), back to the
  // page cache (MADV_DONTNEED on the read-only mapping): a pass over a container larger
  // than memory then keeps a bounded resident set. Later reads fault them back in.
  void release_frame_pages(std::uint64_t k) const;
  void release_point_pages(std::uint64_t first, std::uint64_t n) const;

 private:
  [[noreturn]] void fail(std::uint64_t offset, const std::string& problem) const;
  std::span<const std::uint8_t> section_payload(std::uint64_t offset, std::uint32_t tag, std::uint64_t length,
                                                const std::string& what) const;
  std::span<const std::uint8_t> frame_payload(std::uint64_t k) const;

  std::string path_;
  const SectionEntry* periodic_box_ = nullptr;
  int fd_ = -1;
  const std::uint8_t* data_ = nullptr;
  std::uint64_t size_ = 0;
  std::uint16_t version_major_ = 0, version_minor_ = 0;
  TetFileHeader header_;
  Footer footer_;
  std::vector<SectionEntry> sections_;
  std::vector<FrameEntry> frames_;
  std::uint64_t points_offset_ = 0;  // of PNTS's payload
  std::uint64_t tet_bytes_ = 0;
};

// The order of the symbolic perturbation the file's tets were computed under
// (format.md §3.4): -1 when it is the labels' (version 1); for version 2, the axis the
// points were sorted along, the first of largest extent in HEAD's bounding box: the
// perturbation orders points by their coordinates compared from that axis on.
int perturbation_axis(const TetReader& reader);

// The labels a brick of the file holds (format.md §3.4): 1 for version 1, whose labels
// are in the sort's order; for version 2, brick_labels(N). A point of a later brick
// lies at or above every point of an earlier one along the sort axis.
std::uint64_t label_brick(const TetReader& reader);

}  // namespace tetstream::io
