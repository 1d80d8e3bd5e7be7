#pragma once
// `tetstream field --neighbours`: the Delaunay neighbour rows, back in input order.
//
// Pass 1 (field_accumulate.hpp) hands each point's complete row once, when the point
// retires, in label order: its neighbours' original indices, increasing, no repeats.
// The rows are distributed into B buckets of contiguous original-index ranges, B sized
// from the budget so that one bucket fits in memory when it is written; each bucket's
// rows are buffered, and a full buffer is appended as a chunk to one scratch file. The
// writer takes the buckets in order, places each row by its original index (a direct
// placement, no sort) and streams the CSR arrays front to back.
//
// Why not an external sort of (point, neighbour) pairs (the first version): that
// sorted ~16.5 N records of 16 bytes, spilled at 10^6 points under 1G, and cost more
// than the triangulation itself. Rows arrive complete and sorted, so the only reorder
// left is one of whole rows by a key that is a dense index: a distribution, one write
// and one read of the data when it spills, none at all when it fits (B = 1: 10^6
// points in well under 1G).
//
// Rows are held in 32-bit words: `--neighbours` takes at most 2^32 points (field.cpp),
// so an original index, a degree and a neighbour each fit one (half the memory, the
// scratch file and the placement's traffic of 64-bit words).
//
// The bytes do not depend on the budget or the threads: every row lands at its
// original index whatever bucket or chunk carried it. The entry count is known when
// pass 1 ends, so the index array is written behind its final header directly, and the
// arrays' type can be chosen then: int32 when every offset and index fits (scipy.sparse's
// own choice), int64 otherwise or when asked.
#include "pipeline/files/temp_files.hpp"

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace tetstream::pipeline {

struct NeighbourRowsChunk {
  std::uint64_t offset, words;  // in the scratch file, in 4-byte words
};

class NeighbourRows {
 public:
  // original_end: every original index is below it. entries_bound: the expected
  // number of entries (plans the buckets; more only makes them spill sooner).
  // memory_bytes: the rows' share of the budget. scratch: the chunk file's path
  // (created at the first spill only). Every original index must be below 2^32.
  NeighbourRows(std::uint64_t original_end, std::uint64_t point_count, std::uint64_t entries_bound,
                std::uint64_t memory_bytes, std::string scratch);
  ~NeighbourRows();
  NeighbourRows(const NeighbourRows&) = delete;
  NeighbourRows& operator=(const NeighbourRows&) = delete;

  // One point's row (any order of points; each point once).
  void add(std::uint64_t original, std::span<const std::uint32_t> neighbours);
  // True when the CSR pair would need int64: an offset (up to entries()) or an index
  // (below original_end) past INT32_MAX.
  bool needs_int64() const;
  // Writes the CSR pair as .npy files of int32 (wide false; needs_int64() must be
  // false) or int64: offsets (rows + 1), indices (entries). Throws std::logic_error
  // unless exactly point_count rows were added.
  void write(const std::string& offsets_path, const std::string& indices_path, bool wide);

  std::uint64_t entries() const { return entries_; }
  std::uint64_t buckets() const { return buffers_.size(); }
  bool spilled() const { return spilled_; }

 private:
  void spill(std::size_t bucket);
  // Rows with original in [lo, hi) of bucket b, as [original, degree, neighbours...].
  void load(std::size_t b, std::uint64_t lo, std::uint64_t hi, std::vector<std::uint32_t>& out);
  template <class Index>
  void write_as(const std::string& offsets_path, const std::string& indices_path);

  std::uint64_t original_end_, point_count_, width_, words_per_bucket_, half_words_;
  std::string scratch_;
  std::vector<std::vector<std::uint32_t>> buffers_;      // a bucket's rows not spilled yet
  std::vector<std::vector<NeighbourRowsChunk>> chunks_;  // a bucket's spilled rows
  std::vector<std::uint64_t> bucket_words_;              // a bucket's rows, buffered and spilled
  std::unique_ptr<BinaryFile> file_;
  std::uint64_t file_words_ = 0, entries_ = 0, rows_ = 0;
  bool spilled_ = false;
};

}  // namespace tetstream::pipeline
