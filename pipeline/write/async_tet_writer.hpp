#pragma once
// The writer stage on its own thread: batches of tets go into a bounded queue, and one
// background thread hands them to io::TetWriter::add_tets (which compresses and
// writes), so the producer (the segment loop) overlaps with compression and I/O.
//
//   io::TetWriter writer(path, header);  writer.add_points(...);
//   AsyncTetWriter out(writer, 2);
//   std::vector<std::uint64_t> b = out.take_buffer();  ... fill, 4 labels per tet ...
//   out.add_tets(std::move(b));          ...           // returns at once unless full
//   std::uint64_t committed = out.checkpoint();        // drains first
//   out.add_checkpoint([](std::uint64_t c) { ... });   // or later, on the writer's thread
//   out.finish();                                      // drains, then writer.finish()
//
// Bytes: each batch is one TetWriter::add_tets call, in push order, so the file is
// byte for byte the one that calling the writer directly with the same batches gives.
//
// Memory: at most `capacity` batches wait in the queue, `gather` are being written,
// and the emptied buffers come back through take_buffer() (at most capacity + gather
// + 1 are kept), so the steady state allocates nothing and holds about that many
// batches' worth.
//
// Ownership of the writer: from the first add_tets() until a drain(), checkpoint() or
// finish() returns, the background thread drives the writer; the caller must not touch
// it then (TetWriter is single-threaded). checkpoint() and finish() call the writer on
// the caller's thread, after the drain, so their own errors are thrown directly.
//
// Errors: an exception in the background thread (IoError on a full disk, a bad label)
// is captured, the queue is cancelled (queued batches are dropped, a producer blocked
// on a full queue wakes), and the exception is rethrown exactly once, by the
// producer's next call of add_tets(), drain(), checkpoint() or finish() (or by the one
// blocked at that moment). Every later call of those throws std::logic_error ("used
// after its writer failed"): the error has been reported, and nothing more is written.
// failed() says whether that happened. The destructor never throws, never terminates
// and never hangs: it cancels the queue and joins the thread, which finishes the batch
// it is writing at most. Destroy the TetWriter after this object; it then removes its
// partial file (or keeps it, with TetWriterOptions::keep_partial).
//
// Thread-safety: one producer thread (or calls serialized by the caller, e.g. an
// OpenMP ordered region). The statistics may be read from any thread. With
// TetWriterOptions::threads > 1 the background thread encodes on an OpenMP team of its
// own, beside the producer's threads.
#include "io/tet_writer.hpp"
#include "pipeline/util/bounded_queue.hpp"

#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <functional>
#include <mutex>
#include <span>
#include <thread>
#include <vector>

namespace tetstream::pipeline {

class AsyncTetWriter {
 public:
  // Starts the background thread. capacity: batches that may wait (>= 1). gather: up
  // to this many queued batches are taken at once and handed to the writer together
  // (TetWriter::add_tets of several batches: their frames are encoded on the writer's
  // options.threads), so a burst of batches is compressed on several cores; the
  // bytes are those of one call per batch.
  explicit AsyncTetWriter(io::TetWriter& writer, std::size_t capacity = 2, std::size_t gather = 1);
  ~AsyncTetWriter();
  AsyncTetWriter(const AsyncTetWriter&) = delete;
  AsyncTetWriter& operator=(const AsyncTetWriter&) = delete;

  // An empty vector to fill with the next batch: a recycled one (its capacity kept)
  // when the background thread has handed one back, otherwise a new one.
  std::vector<std::uint64_t> take_buffer();

  // Queues a batch (4 labels per tet; std::invalid_argument at once otherwise) and
  // returns, waiting only while `capacity` batches are queued. An empty batch writes
  // nothing, as TetWriter::add_tets. Rethrows a background failure (see above).
  void add_tets(std::vector<std::uint64_t>&& batch);
  // The same for labels the caller keeps: copied into a recycled buffer.
  void add_tets(std::span<const std::uint64_t> labels);

  // Queues a checkpoint behind the batches queued so far and returns (waiting only
  // while the queue is full): once they are written, the background thread calls
  // TetWriter::checkpoint() and then on_committed(bytes), on its own thread. So the
  // producer never waits for the writer to catch up at a checkpoint (a drain per
  // segment left both cores of a 2-core machine half idle). An exception from either
  // is the background failure (see above).
  void add_checkpoint(std::function<void(std::uint64_t committed)> on_committed);
  // Queues any other use of the writer, run on the background thread in queue order
  // (e.g. the points section, written while the first zones are triangulated). Its
  // exception is the background failure.
  void add_task(std::function<void(io::TetWriter&)> task);

  // Waits until every queued batch and checkpoint is done.
  void drain();
  // drain() + TetWriter::checkpoint(): the byte count to persist for resume().
  std::uint64_t checkpoint();
  // drain(), stops the thread, then TetWriter::finish(). Nothing may follow it.
  void finish();
  // Abandons the job (the producer's own failure): drops the queued batches and stops
  // the thread (after the batch being written). Later calls throw std::logic_error.
  // The destructor does the same. Producer thread only, like the calls above.
  void cancel() noexcept;

  bool failed() const;
  // Seconds the background thread spent in the writer (compressing, writing, checkpoints).
  double busy_seconds() const;
  // Seconds the producer waited for the writer: blocked on a full queue, or draining.
  // The segment loop's time lost to the writer stage (I/O and compression).
  double producer_wait_seconds() const { return producer_wait_seconds_; }
  // The most batches that waited in the queue at once (the one being written aside).
  std::size_t peak_queued() const { return queue_.peak_size(); }
  std::uint64_t batches_written() const;  // batches and checkpoints done

 private:
  void run() noexcept;  // the background thread
  // Throws the background failure the first time, std::logic_error after; else nothing.
  void rethrow_failure_once();
  void check_usable();  // rethrow_failure_once(), then std::logic_error after finish()/cancel()
  void recycle(std::vector<std::uint64_t>&& buffer);
  // Buffers kept for reuse: enough for a full queue, the batch being written and the
  // one the producer fills; more would only be memory held for nothing.
  std::size_t spare_limit() const { return capacity_ + gather_ + 1; }

  // What the queue carries: a batch of tets, or (task set) a use of the writer.
  struct Item {
    std::vector<std::uint64_t> tets;
    std::function<void(io::TetWriter&)> task;
  };
  void push(Item&& item);

  io::TetWriter& writer_;
  const std::size_t capacity_, gather_;
  BoundedQueue<Item> queue_;

  // Shared with the background thread, under mutex_.
  mutable std::mutex mutex_;
  std::condition_variable written_cv_;             // signalled after every batch and on failure
  std::uint64_t written_ = 0;                      // items (batches, checkpoints) done
  std::vector<std::vector<std::uint64_t>> spare_;  // emptied buffers, for take_buffer()
  std::exception_ptr failure_;                     // the background thread's first exception
  bool failure_reported_ = false;                  // rethrown once already
  double busy_seconds_ = 0;

  // Producer-side only.
  std::uint64_t queued_ = 0;  // items pushed (written_ catches up with it in drain())
  bool stopped_ = false;      // finish() or cancel() was called
  double producer_wait_seconds_ = 0;

  std::thread thread_;  // last: started once everything above exists
};

}  // namespace tetstream::pipeline
