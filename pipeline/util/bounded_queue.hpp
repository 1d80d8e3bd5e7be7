#pragma once
// A bounded blocking queue between pipeline stages: producers wait while it is full,
// so a fast stage cannot run ahead of a slow one by more than `capacity` items (the
// memory bound), and consumers wait while it is empty.
//
//   BoundedQueue<Batch> q(4);
//   producer:  while (...) if (!q.push(std::move(batch))) break;   q.close();
//   consumer:  Batch b;  while (q.pop(b)) use(b);
//   either, on failure:  q.cancel();
//
// Two ways to stop, and the difference matters:
//   close()   the producers are done. Items already queued are still delivered; pop()
//             returns false once the queue is closed AND empty. push() after close()
//             returns false.
//   cancel()  abort. Queued items are dropped (destroyed), every waiter wakes, and
//             from then on push() and pop() return false at once. A failing consumer
//             cancels so that a producer blocked on a full queue cannot hang, and a
//             failing producer (or a destructor) cancels so that a consumer blocked
//             on an empty queue cannot hang.
// Both are idempotent, may be called from any thread, and may follow each other in
// either order; cancel() wins over close().
//
// Invariants (under the mutex): size() <= capacity(); once closed or cancelled a queue
// never reopens; after cancel() it holds no items. Items leave in push order (FIFO).
// A push() that returns false has not taken its item: the caller still owns it (the
// rvalue reference is only moved from on success).
//
// Memory: the items live in a ring of `capacity` slots allocated once, so pushing and
// popping allocate nothing (a stage that recycles its buffers runs allocation-free).
//
// Thread-safety: any number of producers and consumers. Wake-ups are notified while
// the mutex is held, so a waiter that wakes and destroys the queue (after its owner's
// join) can never race with a notifier still touching the condition variables.
#include <condition_variable>
#include <cstddef>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <utility>
#include <vector>

namespace tetstream::pipeline {

template <class T>
class BoundedQueue {
 public:
  explicit BoundedQueue(std::size_t capacity) : capacity_(capacity) {
    if (capacity_ == 0) throw std::invalid_argument("BoundedQueue: capacity must be at least 1");
    slots_.resize(capacity_);
  }
  BoundedQueue(const BoundedQueue&) = delete;
  BoundedQueue& operator=(const BoundedQueue&) = delete;

  // Waits for room, then appends `item` and returns true. Returns false (item not
  // taken) when the queue is closed or cancelled, before or while waiting.
  bool push(T&& item) {
    std::unique_lock lock(mutex_);
    not_full_.wait(lock, [&] { return stopped() || count_ < capacity_; });
    if (stopped()) return false;
    slots_[(head_ + count_) % capacity_].emplace(std::move(item));
    ++count_;
    if (count_ > peak_) peak_ = count_;
    not_empty_.notify_one();
    return true;
  }

  // Waits for an item and moves it into `out`: true. False when cancelled, or when
  // closed and empty (`out` is then left as it was).
  bool pop(T& out) {
    std::unique_lock lock(mutex_);
    not_empty_.wait(lock, [&] { return cancelled_ || closed_ || count_ > 0; });
    return take_front(out);
  }

  // pop() without the wait: false when nothing is queued (or when cancelled).
  bool try_pop(T& out) {
    std::lock_guard lock(mutex_);
    return take_front(out);
  }

  // The producers are done: consumers drain what is queued, then pop() returns false.
  void close() {
    std::lock_guard lock(mutex_);
    closed_ = true;
    // Consumers must see the end; producers still waiting for room must give up.
    not_empty_.notify_all();
    not_full_.notify_all();
  }

  // Abort: drops the queued items and wakes every waiter; push() and pop() fail from now on.
  void cancel() noexcept {
    std::lock_guard lock(mutex_);
    cancelled_ = true;
    for (std::optional<T>& slot : slots_) slot.reset();
    count_ = 0;
    not_empty_.notify_all();
    not_full_.notify_all();
  }

  std::size_t capacity() const { return capacity_; }
  std::size_t size() const {
    std::lock_guard lock(mutex_);
    return count_;
  }
  // The most items that were ever queued at once.
  std::size_t peak_size() const {
    std::lock_guard lock(mutex_);
    return peak_;
  }
  bool closed() const {
    std::lock_guard lock(mutex_);
    return closed_;
  }
  bool cancelled() const {
    std::lock_guard lock(mutex_);
    return cancelled_;
  }

 private:
  // Under mutex_: moves the first item into `out`, unless there is none or the queue
  // was cancelled.
  bool take_front(T& out) {
    if (cancelled_ || count_ == 0) return false;
    std::optional<T>& slot = slots_[head_];
    out = std::move(*slot);
    slot.reset();
    head_ = (head_ + 1) % capacity_;
    --count_;
    not_full_.notify_one();
    return true;
  }

  bool stopped() const { return closed_ || cancelled_; }

  const std::size_t capacity_;
  mutable std::mutex mutex_;
  std::condition_variable not_full_, not_empty_;
  std::vector<std::optional<T>> slots_;  // the ring: count_ items from slots_[head_] on
  std::size_t head_ = 0, count_ = 0, peak_ = 0;
  bool closed_ = false, cancelled_ = false;
};

}  // namespace tetstream::pipeline
