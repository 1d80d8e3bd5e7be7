#pragma once
// `mpirun -n K tetstream run IN -o OUT --memory M`: the job of pipeline/run.hpp on K
// processes (ranks) that share a filesystem, writing the same bytes as one process
// with the same --memory (M is each rank's budget). docs/scaling.md describes it.
//
//   sort         every rank: each reads a K-th of the input and sorts its key range
//                into its place in OUT.partial's points section
//                (pipeline/point_sort_distributed.hpp); text input: rank 0 alone;
//   index        each rank builds a K-th of the point index's blocks into one file of
//                the work directory, and every rank maps all of it (its emptiness
//                queries reach anywhere);
//   plan         every rank computes the zone plan from the same indexes;
//   triangulate  the labels are cut into blocks of frame_block_labels() labels
//                (pipeline/frame_cutter.hpp), and rank r takes a contiguous run of
//                blocks, about a K-th of the points: its segments and zones on its
//                threads, its frames cut as one process cuts them (a frame never spans
//                two blocks), rank 0's into OUT.partial after the points, rank r's
//                into a fragment file in the job's work directory; one progress line
//                (rank 0's) counts every rank's labels;
//   place        each rank copies its fragment into its place in OUT.partial; rank 0
//                indexes the placed frames, writes the index and footer, renames.
//
// Every phase ends with the ranks agreeing (pipeline/communicator.hpp): a rank that
// fails stops every rank with its error line and exit code.
//
// Checkpoint: rank 0's is the single process's (OUT.tets.ckpt: the sort, its own
// frames' record), which also records the number of ranks; rank R keeps its record
// (rank-R.json), its pending frame and its fragment in the same directory, which rank
// 0 locks, clears (--force) and removes (on success) with every rank's files in it.
// `--resume` under the same number of ranks continues every rank from its record and
// ends with the same bytes. Under another number of ranks it keeps what does not
// depend on it, the sort and rank 0's frames (rank 0's range then reaches at least
// their end), and the other ranks triangulate the rest again (each fragment held its
// old rank's labels): the same bytes too. Without a checkpoint (--no-checkpoint) the
// files go in a temporary directory, and a failure leaves nothing.
//
// Not distributed yet: verify.
#include "pipeline/util/communicator.hpp"
#include "pipeline/run/run.hpp"

namespace tetstream::pipeline {

// Rank 0's summary holds the job's totals and each rank's figures (RunSummary::ranks);
// the other ranks return theirs alone.
RunSummary run_job_distributed(const RunOptions& options, Communicator& comm);

}  // namespace tetstream::pipeline
