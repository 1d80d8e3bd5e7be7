#pragma once
// The sort's merge writing the sorted records straight into the output container's
// points section (docs/format.md 3.4), in OUT.partial, so that the points are on disk
// once: the index and the triangulation map that region of the partial file, and the
// writer appends the tet frames after it (pipeline/stage_write.hpp).
//
// The layout is fixed before the merge but for two header fields that only the merge
// learns: the point count N (8 bytes in HEAD, and the PNTS length) and the duplicates
// merged (a number in HEAD's options text, whose digits move the points section). The
// records go after a header written as if no duplicate were merged; at the end the
// header is written with the real values, and when the options text came out longer
// (10 or more duplicates) the records are moved down by the difference first, one
// pass over them in place from the end (a rare extra pass, never a second copy).
//
// Writes through the job's claim on the output (its descriptor: no link is followed),
// never truncating: a resumed job that sorts again (a damaged points section) writes
// the same bytes in place, and the frames after them stay. The writer cuts the file
// to its committed bytes when it starts (TetWriter::resume).
#include "io/tet_container.hpp"
#include "pipeline/sort/point_sort.hpp"

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace tetstream::pipeline {

// Rewrites the header of a points section already in the partial output (fd, path)
// for `header` (same points: only its options text may differ, e.g. the budget a
// resumed job writes the frames with), moving the records and their CRC when the
// header's length changes, and sets points.offset. Before anything maps the points;
// a crash midway leaves bytes that fail the recorded CRC, and the job sorts again.
void rewrite_points_header(int fd, SortedPoints& points, const io::TetFileHeader& header, bool sync);

// The bytes before the points' payload (preamble, HEAD, the PNTS section's header) for
// `header(points)`, resolved.
std::vector<std::uint8_t> points_lead(const std::function<io::TetFileHeader(const SortedPoints&)>& header,
                                      const SortedPoints& points);
// Where the merge starts writing the payload: after the lead of the header as laid out
// before the merge (the count a placeholder, no duplicate merged); the real lead is at
// least as long (OutputPointsSink::finish moves the records when it is longer).
std::uint64_t payload_offset_before_merge(const std::function<io::TetFileHeader(const SortedPoints&)>& header,
                                          const SortedPoints& before);
// Moves n bytes of the file from offset `from` to `to`, in place (overlap allowed);
// IoError naming `path` when it cannot.
void move_file_bytes(int fd, const std::string& path, std::uint64_t from, std::uint64_t to, std::uint64_t n);

// Records written with pwrite into a file from byte `offset` on, through a 1 MiB
// buffer, with the CRC32C of their bytes: the merge's output into a points section
// (one process's, or a rank's part of it: pipeline/point_sort_distributed.cpp).
class PayloadWriter {
 public:
  PayloadWriter(int fd, std::string path, std::uint64_t offset);
  void write(const void* data, std::size_t bytes);
  void flush();  // IoError naming the file when it cannot write
  std::uint64_t offset() const { return offset_; }
  std::uint64_t written() const { return written_; }  // flushed or buffered
  std::uint32_t crc() const { return crc_; }
  int fd() const { return fd_; }
  const std::string& path() const { return path_; }

 private:
  int fd_;
  std::string path_;
  std::uint64_t offset_, written_ = 0;
  std::uint32_t crc_ = 0;
  std::vector<char> buffer_;
};

class OutputPointsSink final : public SortedSink {
 public:
  // `header(points)`: the container's header for the sorted points as the merge
  // leaves them (count, duplicates) (stage_write.hpp: container_header).
  // `before`: the sort's result before the merge (no count, no duplicates yet).
  OutputPointsSink(int fd, std::string partial_path, std::function<io::TetFileHeader(const SortedPoints&)> header,
                   const SortedPoints& before);
  void write(const void* data, std::size_t bytes) override;
  void finish(SortedPoints& result, bool sync) override;

 private:
  std::function<io::TetFileHeader(const SortedPoints&)> header_;
  PayloadWriter payload_;  // from the payload's offset as laid out before the merge
};

}  // namespace tetstream::pipeline
