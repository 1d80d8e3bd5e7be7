#pragma once
// `mpirun -n K tetstream run IN -o OUT --memory M`: the job of pipeline/run.hpp on K
// processes (ranks) that share a filesystem, writing the same bytes as one process
// with the same --memory (M is each rank's budget). docs/scaling.md describes it.
//
//   sort         rank 0 (the others wait): the sorted points go into OUT.partial's
//                points section, as in one process;
//   index        every rank maps the sorted points of OUT.partial and builds the
//                indexes over all of them (its emptiness queries reach anywhere);
//   plan         every rank computes the same zone plan from the same indexes;
//   triangulate  the labels are cut into blocks of frame_block_labels() labels
//                (pipeline/frame_cutter.hpp), and rank r takes a contiguous run of
//                blocks, about a K-th of the points: its segments and zones on its
//                threads, its frames cut as one process cuts them (a frame never spans
//                two blocks), rank 0's into OUT.partial after the points, rank r's
//                into a fragment file in the job's work directory;
//   assemble     rank 0 appends the fragments in rank order (each frame's section,
//                CRC and header checked), writes the index and footer, renames.
//
// Every phase ends with the ranks agreeing (pipeline/communicator.hpp): a rank that
// fails stops every rank with its error line and exit code.
//
// Checkpoint: rank 0's is the single process's (OUT.tets.ckpt: the sort, its own
// frames' record), which also records the number of ranks; rank R keeps its record
// (rank-R.json), its pending frame and its fragment in the same directory, which rank
// 0 locks, clears (--force) and removes (on success) with every rank's files in it.
// `--resume` under the same number of ranks continues every rank from its record and
// ends with the same bytes (another number is refused before any rank writes: each
// fragment holds its rank's labels). Without a checkpoint (--no-checkpoint) the files
// go in a temporary directory, and a failure leaves nothing.
//
// Not distributed yet: the sort (rank 0 alone, the others wait), the indexes (every
// rank builds all of them), verify.
#include "pipeline/communicator.hpp"
#include "pipeline/run.hpp"

namespace tetstream::pipeline {

// Rank 0's summary holds the job's totals and each rank's figures (RunSummary::ranks);
// the other ranks return theirs alone.
RunSummary run_job_distributed(const RunOptions& options, Communicator& comm);

// The label ranges of `ranks` ranks over `count` labels: contiguous runs of whole
// blocks of `block` labels, balanced by points; bounds[r] to bounds[r + 1] is rank
// r's (empty when there are fewer blocks than ranks).
std::vector<std::uint64_t> rank_label_bounds(std::uint64_t count, std::uint64_t block, int ranks);

}  // namespace tetstream::pipeline
