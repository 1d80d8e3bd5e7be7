#include "pipeline/write/points_reorder.hpp"

#include "core/error.hpp"
#include "io/output_file.hpp"
#include "io/tet_container.hpp"
#include "pipeline/util/interrupt.hpp"
#include "pipeline/write/label_order.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <vector>

namespace tetstream::pipeline {

namespace {

void read_at(int fd, void* data, std::size_t n, std::uint64_t at) {
  if (!io::pread_exactly(fd, data, n, at))
    throw IoError("points: read failed at byte " + std::to_string(at) + ": " + std::strerror(errno));
}

void write_at(int fd, const void* data, std::size_t n, std::uint64_t at) {
  if (!io::pwrite_exactly(fd, data, n, at))
    throw IoError("points: write failed at byte " + std::to_string(at) + ": " + std::strerror(errno));
}

}  // namespace

std::uint32_t reorder_points(int fd, std::uint64_t payload_offset, RecordLayout layout, const LabelOrder& order) {
  const std::uint64_t count = order.point_count(), brick = order.brick();
  const std::size_t rec = layout.bytes();
  // A batch of bricks of ~64 MiB at a time: one read and one write each.
  const std::uint64_t batch = brick * std::max<std::uint64_t>(1, (std::uint64_t(64) << 20) / (brick * rec));
  std::vector<std::uint8_t> sorted, reordered;
  std::vector<std::uint32_t> new_of_old;
  std::uint32_t crc = 0;
  for (std::uint64_t first = 0; first < count; first += batch) {
    check_interrupted();
    const std::uint64_t end = std::min(count, first + batch);
    const std::size_t bytes = std::size_t(end - first) * rec;
    const std::uint64_t at = payload_offset + first * rec;
    sorted.resize(bytes);
    reordered.resize(bytes);
    read_at(fd, sorted.data(), bytes, at);
    for (std::uint64_t f = first; f < end; f += brick) {
      order.read_brick(f / brick, new_of_old);
      const std::uint8_t* in = sorted.data() + (f - first) * rec;
      std::uint8_t* out = reordered.data() + (f - first) * rec;
      for (std::size_t i = 0; i < new_of_old.size(); ++i)
        std::memcpy(out + std::size_t(new_of_old[i]) * rec, in + i * rec, rec);
    }
    write_at(fd, reordered.data(), bytes, at);
    crc = io::crc32c(reordered.data(), bytes, crc);
  }
  std::uint8_t trailer[4];
  io::put_u32(trailer, crc);
  write_at(fd, trailer, sizeof trailer, payload_offset + count * rec);
  return crc;
}

}  // namespace tetstream::pipeline
