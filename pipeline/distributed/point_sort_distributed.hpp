#pragma once
// The sort of a job under MPI (pipeline/run_distributed.hpp), spread over its K ranks so
// that no rank reads, holds or writes more than its part of the points:
//
//   scan      rank r reads the r-th K-th of the input's records (in input order; binary
//             formats seek to it) for the bounding box, and a regular sample of keys;
//   splitters rank 0 sorts the samples and cuts the sort order into K ranges of about
//             equal counts, by coordinates alone, so that exact duplicates (equal
//             coordinates) meet on one rank and are merged there as in one process;
//   exchange  in rounds of bounded size, each rank reads the next chunk of its records
//             and sends each one to the rank of its range (one all-to-all a round);
//             each rank sorts what it receives into runs, finding their hull
//             candidates, as one process does (pipeline/point_sort_detail.hpp);
//   merge     each rank merges its runs straight into the output's points section;
//   close     the ranks' counts, duplicates, hull candidates and checksums are
//             gathered; rank 0 writes the header and the section's checksum (combined
//             from the ranks' with io::crc32c_combine, no byte read again).
//
// The result is the bytes of the one-process sort: the same order, labels (a rank's
// follow those of the ranks before it), duplicates kept (the first in input order),
// header and checksum. The hull candidates are the union of the ranks' (each a superset
// of the boundary points of its own points' hull: pipeline/hull.hpp), so the index
// stage finds the same hull.
//
// Where a rank's merge writes: its first label is known only once every merge has
// counted its duplicates. Each rank writes where its records would start if none were
// merged (the header laid out before the merge, the ranks before it counted by the
// records they received); when duplicates were merged the parts are then moved into
// place, those moving towards the file's start in rank order, then those moving towards
// its end in reverse order, so that no part overwrites one not yet moved (a rare extra
// pass, as one process's when its header grows).
//
// Memory: the rank's sort shares of its ledger (MemoryBudget::plan_sort), the round's
// send buffer and read chunk taken out of its run buffer. Not resumable midway: a job
// stopped before the sort finished sorts again.
#include "io/output_file.hpp"
#include "io/point_reader.hpp"
#include "io/tet_container.hpp"
#include "pipeline/util/communicator.hpp"
#include "pipeline/sort/point_sort.hpp"

#include <functional>
#include <string>

namespace tetstream::pipeline {

// Where the ranks write the sorted points: the claimed output's partial file.
struct DistributedSortTarget {
  std::string partial;                // OUT.partial
  io::OutputPart::Identity identity;  // the file rank 0's claim holds (every rank checks it)
  // Rank 0: the container header for given sorted points (SortStage::points_header).
  std::function<io::TetFileHeader(const SortedPoints&)> header;
};

// Whether the sort can be spread over ranks: the input's reader knows its count up
// front (raw files, PLY, npy, LAS, HDF5), so each rank can find its range. Text input
// is sorted by rank 0 alone.
bool sorts_by_ranges(const std::string& input, const io::PointReadOptions& read_options);

// Every rank calls it, in the same step. `dir`: the job's work directory, where this
// rank's runs are `runs_name`-K.run (each rank a name of its own). Rank 0 returns the SortedPoints of the whole sort
// (its path and offset in the output's partial file); the others return their part's counts only. Errors as together()
// reports them (pipeline/communicator.hpp): one line from the lowest rank that failed (an input error at the first bad
// record in input order, as one process).
SortedPoints sort_points_distributed(Communicator& comm, const std::string& input,
                                     const io::PointReadOptions& read_options, const PointSortOptions& options,
                                     const std::string& dir, const std::string& runs_name,
                                     const DistributedSortTarget& target);

}  // namespace tetstream::pipeline
