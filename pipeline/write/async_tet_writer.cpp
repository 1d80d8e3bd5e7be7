#include "pipeline/write/async_tet_writer.hpp"

#include <algorithm>
#include <chrono>
#include <optional>
#include <stdexcept>
#include <utility>

namespace tetstream::pipeline {

namespace {
using Clock = std::chrono::steady_clock;
}  // namespace

AsyncTetWriter::AsyncTetWriter(io::TetWriter& writer, std::size_t capacity, std::size_t gather)
    : writer_(writer), capacity_(capacity), gather_(std::max<std::size_t>(gather, 1)), queue_(capacity) {
  // Reserved now so that handing buffers back never allocates (see recycle()).
  spare_.reserve(spare_limit());
  thread_ = std::thread([this] { run(); });
}

AsyncTetWriter::~AsyncTetWriter() { cancel(); }

void AsyncTetWriter::run() noexcept {
  // Batches taken together; a task met while gathering waits in `next`, behind them.
  std::vector<Item> items;
  std::optional<Item> next;
  std::vector<std::span<const std::uint64_t>> spans;
  try {
    for (;;) {
      items.clear();
      if (next) {
        items.push_back(std::move(*next));
        next.reset();
      } else {
        items.emplace_back();
        if (!queue_.pop(items.back())) break;
      }
      if (!items.front().task) {
        Item more;
        while (items.size() < gather_ && queue_.try_pop(more)) {
          if (more.task) {
            next = std::move(more);
            break;
          }
          items.push_back(std::move(more));
        }
      }
      const auto t0 = Clock::now();
      if (items.front().task) {
        items.front().task(writer_);
      } else {
        spans.clear();
        for (const Item& item : items) spans.emplace_back(item.tets);
        writer_.add_tets(std::span<const std::span<const std::uint64_t>>(spans));
      }
      const double seconds = std::chrono::duration<double>(Clock::now() - t0).count();
      std::lock_guard lock(mutex_);
      busy_seconds_ += seconds;
      written_ += items.size();
      for (Item& item : items) {
        item.tets.clear();
        // A full spare list lets this buffer go with `items`.
        if (item.tets.capacity() > 0 && spare_.size() < spare_limit()) spare_.push_back(std::move(item.tets));
      }
      written_cv_.notify_all();
    }
  } catch (...) {
    // failure_ is set before the queue is cancelled: a producer that sees its push()
    // fail (or its drain() wake) then always finds the error to rethrow.
    {
      std::lock_guard lock(mutex_);
      failure_ = std::current_exception();
      written_cv_.notify_all();
    }
    queue_.cancel();
  }
}

void AsyncTetWriter::rethrow_failure_once() {
  std::exception_ptr failure;
  {
    std::lock_guard lock(mutex_);
    if (!failure_) return;
    if (failure_reported_) throw std::logic_error("AsyncTetWriter: used after its writer failed");
    failure_reported_ = true;
    failure = failure_;
  }
  std::rethrow_exception(failure);
}

void AsyncTetWriter::check_usable() {
  rethrow_failure_once();
  if (stopped_) throw std::logic_error("AsyncTetWriter: used after finish() or cancel()");
}

std::vector<std::uint64_t> AsyncTetWriter::take_buffer() {
  std::lock_guard lock(mutex_);
  if (spare_.empty()) return {};
  std::vector<std::uint64_t> b = std::move(spare_.back());
  spare_.pop_back();
  return b;
}

void AsyncTetWriter::recycle(std::vector<std::uint64_t>&& buffer) {
  buffer.clear();
  std::lock_guard lock(mutex_);
  if (spare_.size() < spare_limit()) spare_.push_back(std::move(buffer));
}

void AsyncTetWriter::add_tets(std::vector<std::uint64_t>&& batch) {
  check_usable();
  if (batch.size() % 4 != 0) throw std::invalid_argument("AsyncTetWriter: tet labels must come 4 per tet");
  if (batch.empty()) {
    recycle(std::move(batch));
    return;
  }
  push(Item{std::move(batch), nullptr});
}

void AsyncTetWriter::add_checkpoint(std::function<void(std::uint64_t)> on_committed) {
  check_usable();
  if (!on_committed) throw std::invalid_argument("AsyncTetWriter: a checkpoint needs a callback");
  add_task([on_committed = std::move(on_committed)](io::TetWriter& w) { on_committed(w.checkpoint()); });
}

void AsyncTetWriter::add_task(std::function<void(io::TetWriter&)> task) {
  check_usable();
  if (!task) throw std::invalid_argument("AsyncTetWriter: an empty task");
  push(Item{{}, std::move(task)});
}

void AsyncTetWriter::push(Item&& item) {
  const auto t0 = Clock::now();
  const bool pushed = queue_.push(std::move(item));
  producer_wait_seconds_ += std::chrono::duration<double>(Clock::now() - t0).count();
  if (!pushed) {
    // Only the background thread's failure cancels the queue while the producer is
    // still using it (finish() and cancel() are the producer's own calls), and it
    // records the failure first.
    rethrow_failure_once();
    throw std::logic_error("AsyncTetWriter: queue stopped without an error");  // unreachable
  }
  ++queued_;
}

void AsyncTetWriter::add_tets(std::span<const std::uint64_t> labels) {
  check_usable();  // before the copy: a failed writer takes nothing more
  std::vector<std::uint64_t> b = take_buffer();
  b.assign(labels.begin(), labels.end());
  add_tets(std::move(b));
}

void AsyncTetWriter::drain() {
  check_usable();
  const auto t0 = Clock::now();
  {
    std::unique_lock lock(mutex_);
    written_cv_.wait(lock, [&] { return failure_ || written_ == queued_; });
  }
  producer_wait_seconds_ += std::chrono::duration<double>(Clock::now() - t0).count();
  rethrow_failure_once();
}

std::uint64_t AsyncTetWriter::checkpoint() {
  drain();
  return writer_.checkpoint();
}

void AsyncTetWriter::finish() {
  drain();
  stopped_ = true;
  // The queue is empty and the thread idle in pop(): close() lets it leave its loop.
  queue_.close();
  thread_.join();
  writer_.finish();
}

void AsyncTetWriter::cancel() noexcept {
  stopped_ = true;
  queue_.cancel();
  if (thread_.joinable()) thread_.join();
}

bool AsyncTetWriter::failed() const {
  std::lock_guard lock(mutex_);
  return bool(failure_);
}

double AsyncTetWriter::busy_seconds() const {
  std::lock_guard lock(mutex_);
  return busy_seconds_;
}

std::uint64_t AsyncTetWriter::batches_written() const {
  std::lock_guard lock(mutex_);
  return written_;
}

}  // namespace tetstream::pipeline
