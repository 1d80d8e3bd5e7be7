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
#include "pipeline/point_sort.hpp"

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
  void flush();

  int fd_;
  std::string path_;
  std::function<io::TetFileHeader(const SortedPoints&)> header_;
  std::uint64_t offset_ = 0;    // of the payload, as laid out before the merge
  std::uint64_t written_ = 0;   // payload bytes written (flushed or buffered)
  std::uint32_t crc_ = 0;
  std::vector<char> buffer_;
};

}  // namespace tetstream::pipeline
