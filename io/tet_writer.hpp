#pragma once
// Writes a .tets container (docs/format.md), streaming, in bounded memory.
//
//   io::TetFileHeader h;  h.point_count = n;  h.bbox_min = ...;  h.options = json;
//   io::TetWriter w("out.tets", h);
//   w.add_points(xyz, ids, k);   ...     // all points, in label (sorted) order, in chunks
//   w.add_tets(labels);          ...     // batches of tets, 4 labels each
//   w.finish();                          // index + footer, fsync, rename into place
//
// Lifecycle: the file is "out.tets.partial" until finish() renames it; a writer
// destroyed without finish() (an exception, a cancelled job) removes it, so a file
// named out.tets is always complete. For a resumable job, checkpoint() returns a byte
// count to persist, and TetWriter::resume() reopens the partial file at it; with
// options.keep_partial the partial file also survives a failure (disk full, a
// cancelled job), so that the job can be resumed from its last checkpoint.
//
// Frames: add_tets() splits a batch into frames of at most options.frame_tets and
// encodes them on up to options.threads OpenMP threads (1 by default, so a writer stage
// does not compete with the kernel's threads); the bytes do not depend on the count. A pipeline that encodes elsewhere
// uses io::FrameEncoder (one per thread) and hands the frames to add_frame() in sequence order.
//
// Memory: one write buffer, the frame index (40 bytes per frame), and per encoding
// thread one frame's scratch (about 40 bytes per tet of frame_tets) and encoded bytes.
// Thread-safety: none; one thread drives a writer.
#include "io/tet_codec.hpp"
#include "io/tet_container.hpp"

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace tetstream::io {

class OutputFile;
class OutputClaim;

struct TetWriterOptions {
  int zstd_level = kDefaultZstdLevel;
  std::uint32_t frame_tets = kDefaultFrameTets;  // most tets per frame, 1..kMaxFrameTets
  int threads = 1;                               // add_tets() encoders (OpenMP); 0: omp_get_max_threads()
  bool sync = true;                              // fsync before the rename (and in checkpoint())
  std::size_t buffer_bytes = std::size_t(8) << 20;
  // Destroyed without finish(): leave PATH.partial in place (closed, not flushed: only
  // what checkpoint() returned is certain) instead of removing it. For resumable jobs.
  // resume() honours it too: a resume refused by its checks leaves the file in place
  // (already cut back to `committed` bytes).
  bool keep_partial = false;
  // The job's claim on the output (io/output_file.hpp), taken before its work began;
  // null: the writer claims the output itself.
  const OutputClaim* claim = nullptr;
  // resume() only: the CRC32C of the points' payload, when the caller has just checked
  // or written those bytes itself (a job whose sort merged the points into the partial
  // file): the stored CRC is compared with it instead of reading the points again (a
  // pass over 28 GB at 10^9 points).
  std::optional<std::uint32_t> points_crc;
};

// The bytes a container of `header` (resolved: TetFileHeader::resolve_and_validate)
// starts with: the preamble, HEAD, and the PNTS section's header; the points' payload
// follows them.
std::vector<std::uint8_t> leading_bytes(const TetFileHeader& header);

// Copies the frames of a finished fragment file (TetWriter::fragment()) into the
// partial file of a container that another process is writing, from byte `at` on, with
// pwrite; checks each frame's section, CRC and frame header (InputError naming the
// fragment and the offset otherwise), and syncs what it wrote. Neither file is
// opened through a link; the container must be the regular file `container_file`
// (st_dev, st_ino) names. Returns the frames as placed (absolute offsets; first_tet
// counted from the fragment's first tet), for that writer's adopt_placed_frames(). So
// the ranks of a job under MPI put their own frames in place side by side, and rank 0
// copies nothing.
std::vector<FrameEntry> place_fragment(const std::string& fragment, const std::string& container_partial,
                                       std::uint64_t at, std::uint64_t point_count,
                                       std::pair<std::uint64_t, std::uint64_t> container_file);

class TetWriter {
 public:
  // Creates PATH.partial and writes the preamble and HEAD. The header's widths are
  // resolved (label width 32 when point_count <= 2^32) and it is validated:
  // std::invalid_argument for a header no container can hold, IoError for I/O.
  // PATH "-" streams the container to standard output (io::OutputFile::to_stdout).
  TetWriter(std::string path, TetFileHeader header, TetWriterOptions options = {});
  // Continues PATH.partial, left by a writer with the same header and options, after
  // its first `committed` bytes (a value its checkpoint() returned): checks the header
  // bytes, rebuilds the frame index from the frames there (checking their CRCs) and
  // drops anything after them. Throws InputError when the partial file does not match.
  static std::unique_ptr<TetWriter> resume(std::string path, TetFileHeader header, std::uint64_t committed,
                                           TetWriterOptions options = {});
  // A fragment: PATH.partial holding frames only (TETF sections, no preamble, header,
  // points, index or footer), the frames of a label range that place_fragment() puts
  // into their place in the container (the ranks of a job under MPI). Its
  // frames are added as a container's are; finish() renames it to PATH.
  static std::unique_ptr<TetWriter> fragment(std::string path, TetFileHeader header, TetWriterOptions options = {});
  // Continues a fragment's PATH.partial after its first `committed` bytes (a value its
  // checkpoint() returned), as resume() continues a container.
  static std::unique_ptr<TetWriter> resume_fragment(std::string path, TetFileHeader header, std::uint64_t committed,
                                                    TetWriterOptions options = {});
  ~TetWriter();
  TetWriter(const TetWriter&) = delete;
  TetWriter& operator=(const TetWriter&) = delete;

  const TetFileHeader& header() const { return header_; }

  // The next n points in label order: xyz holds 3n coordinates, ids n original
  // indices (nullptr: each point's original index is its label). Every point must lie
  // in the header's bounding box, and all point_count points must come before the
  // first tet (std::logic_error / std::invalid_argument otherwise).
  void add_points(const double* xyz, const std::uint64_t* ids, std::size_t n);
  void add_points(const float* xyz, const std::uint64_t* ids, std::size_t n);

  // A batch of tets, 4 labels each (< point_count, distinct, positively oriented).
  void add_tets(std::span<const std::uint32_t> labels);
  void add_tets(std::span<const std::uint64_t> labels);
  // Several batches at once, written as the same calls one after the other would
  // write them (the same bytes), but their frames encoded together, options.threads
  // at a time: a writer stage handed a burst of batches keeps several cores busy.
  void add_tets(std::span<const std::span<const std::uint64_t>> batches);
  // One frame from FrameEncoder, appended as the next frame.
  void add_frame(const EncodedFrame& frame);
  // The frames that place_fragment() put into this container's partial file after its
  // last byte (`bytes` of them; `frames` in order, their offsets absolute): indexed as
  // its next frames, the container then holding the bytes of one writer that wrote
  // them itself. Flushes first.
  void adopt_placed_frames(std::span<const FrameEntry> frames, std::uint64_t bytes);

  // A critical section of another kind (a periodic container's PBOX and POFS,
  // docs/format.md §6) at the current position, listed in the directory: after the
  // points, between frames or after the last one.
  void add_section(std::uint32_t tag, std::span<const std::uint8_t> payload);

  // Flushes (and syncs, if options.sync) everything written so far and returns the
  // size of the partial file: the `committed` argument of resume(). Call it between
  // batches, after the points.
  std::uint64_t checkpoint();
  // Writes INDX and the footer, syncs, renames PATH.partial to PATH.
  void finish();
  // Gives up this output: PATH.partial is emptied and left to the job's claim (a later
  // writer under it starts over; the claim removes it, empty, when the job ends), and
  // the writer takes no more. Not on standard output.
  void discard();

  std::uint64_t points_written() const { return points_; }
  std::uint64_t tets_written() const { return tets_; }
  std::uint64_t frames_written() const { return frames_.size(); }
  std::uint64_t bytes_written() const;
  // Bytes of the tet frames written so far (section headers and trailers included).
  std::uint64_t tet_bytes() const;

 private:
  struct Resume {};
  TetWriter(Resume, std::string path, TetFileHeader header, TetWriterOptions options);
  template <class F>
  void add_points_impl(const F* xyz, const std::uint64_t* ids, std::size_t n);
  template <class L>
  void add_tets_impl(std::span<const std::span<const L>> batches);
  void write_section_start(std::uint32_t tag, std::uint64_t length);
  // The sections from `at` on that are not frames (before the first one), checked and
  // indexed; returns where the frames start (or `committed`).
  std::uint64_t skip_leading_section(std::uint64_t at, std::uint64_t committed);
  void rebuild_frame_index(std::uint64_t from, std::uint64_t committed);

  std::string path_;
  TetFileHeader header_;
  TetWriterOptions options_;
  std::unique_ptr<OutputFile> out_;
  std::vector<SectionEntry> sections_;
  std::vector<FrameEntry> frames_;
  std::uint64_t points_ = 0, tets_ = 0;
  std::uint32_t points_crc_ = 0;
  std::uint64_t points_end_ = 0;  // offset just after the PNTS section
  bool finished_ = false;
  bool fragment_ = false;  // frames only (fragment())
  std::vector<std::unique_ptr<FrameEncoder>> encoders_;
  std::vector<EncodedFrame> batch_;
};

}  // namespace tetstream::io
