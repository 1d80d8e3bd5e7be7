#pragma once
// The points section of a partial output put in format 2's label order
// (pipeline/write/label_order.hpp), in place, brick by brick, once every frame is
// written: the triangulation reads the points in the sort's order until its end (an
// emptiness query may read any of them), so they cannot move before.
//
// A crash while it runs leaves the section neither in one order nor the other: its CRC
// matches neither, so a resumed job sorts the points again (SortStage: a sorted region
// that fails its checksum is sorted again, to the same bytes) and rewrites them; the
// frames, all written before, are kept. Last, the section's CRC32C goes into its trailer.
#include "pipeline/sort/point_record.hpp"
#include "pipeline/write/label_order.hpp"

#include <cstdint>

namespace tetstream::pipeline {

// `fd`: the partial output, open for reading and writing. The section's payload starts
// at `payload_offset` and holds the records of `layout` in the sort's order, as many as
// `order` has labels; each brick goes where `order` (the job's label order file) says.
// Returns the new CRC32C of the payload (written into the trailer).
std::uint32_t reorder_points(int fd, std::uint64_t payload_offset, RecordLayout layout, const LabelOrder& order);

}  // namespace tetstream::pipeline
