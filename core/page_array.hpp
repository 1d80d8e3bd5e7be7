#pragma once
// An array of trivially copyable elements in an anonymous mapping of its own, for the
// kernel's largest array (its tets, 32 bytes each, ~7 a point).
//
// Why not std::vector: a vector grows by allocating twice its capacity and copying,
// so a 250 MiB tet array that outgrows its reservation holds 750 MiB for a moment and
// 500 MiB afterwards; and a kernel reused from window to window keeps the capacity of
// its largest window for good: both put the triangulation far past its memory
// budget on windows of uneven size. Here growth is mremap: the pages move, nothing is
// copied and nothing is held twice; and release_beyond() hands back the pages past
// what the next window needs, so resident memory follows the window in use, not the
// largest one ever seen.
//
// Invariants: [data(), data() + size()) are the elements; capacity() >= size() is
// the mapping's length in elements (virtual: a page costs memory once touched).
// Fresh pages read as zero. Not thread-safe; elements must not hold pointers into
// the array across a growth (the mapping may move).
#include "core/huge_pages.hpp"

#include <cstddef>
#include <cstdint>
#include <new>
#include <type_traits>
#include <utility>

#if defined(__linux__)
#include <sys/mman.h>
#else
#include <cstdlib>
#include <cstring>
#endif

namespace tetstream::core {

template <class T>
class PageArray {
  static_assert(std::is_trivially_copyable_v<T> && std::is_trivially_destructible_v<T>);

 public:
  PageArray() = default;
  ~PageArray() { unmap(); }
  PageArray(const PageArray&) = delete;
  PageArray& operator=(const PageArray&) = delete;
  PageArray(PageArray&& o) noexcept { swap(o); }
  PageArray& operator=(PageArray&& o) noexcept {
    swap(o);
    return *this;
  }

  T* data() { return data_; }
  const T* data() const { return data_; }
  std::size_t size() const { return size_; }
  std::size_t capacity() const { return capacity_; }
  bool empty() const { return size_ == 0; }
  T& operator[](std::size_t i) { return data_[i]; }
  const T& operator[](std::size_t i) const { return data_[i]; }
  T* begin() { return data_; }
  T* end() { return data_ + size_; }
  const T* begin() const { return data_; }
  const T* end() const { return data_ + size_; }

  // Room for n elements without moving (the mapping grows to a whole number of 2 MiB
  // huge pages). Throws std::bad_alloc when the system refuses.
  void reserve(std::size_t n) {
    if (n <= capacity_) return;
    const std::size_t bytes = round_up(n * sizeof(T));
#if defined(__linux__)
    void* p = data_ ? mremap(data_, mapped_bytes(), bytes, MREMAP_MAYMOVE)
                    : mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) throw std::bad_alloc();
#else
    void* p = std::realloc(data_, bytes);
    if (!p) throw std::bad_alloc();
#endif
    data_ = static_cast<T*>(p);
    bytes_ = bytes;
    capacity_ = bytes / sizeof(T);
    advise_huge_pages(data_, bytes);
  }

  // Appends a value-initialised element. Growth adds a quarter: the mapping moves
  // without a copy, so a small step costs little and overshoots little.
  T& emplace_back() {
    if (size_ == capacity_) reserve(capacity_ + capacity_ / 4 + kStep / sizeof(T));
    return *new (data_ + size_++) T{};
  }
  void push_back(const T& v) { emplace_back() = v; }
  void clear() { size_ = 0; }
  // n copies of v (the previous elements are dropped).
  void assign(std::size_t n, const T& v) {
    clear();
    reserve(n);
    for (std::size_t i = 0; i < n; ++i) push_back(v);
  }

  // Hands the pages past the first n elements back to the system (they read as zero
  // when touched again), keeping the mapping; n below size() is clamped to size().
  void release_beyond(std::size_t n) {
#if defined(__linux__)
    if (n < size_) n = size_;
    const std::size_t keep = round_up(n * sizeof(T));
    if (data_ && keep < mapped_bytes())
      madvise(reinterpret_cast<char*>(data_) + keep, mapped_bytes() - keep, MADV_DONTNEED);
#else
    (void)n;
#endif
  }

  // Bytes of the mapping (virtual; the resident part is what has been touched).
  std::size_t mapped_bytes() const { return bytes_; }

 private:
  static constexpr std::size_t kStep = std::size_t(1) << 21;  // a huge page
  static std::size_t round_up(std::size_t bytes) { return (bytes + kStep - 1) / kStep * kStep; }
  void unmap() {
#if defined(__linux__)
    if (data_) munmap(data_, mapped_bytes());
#else
    std::free(data_);
#endif
    data_ = nullptr;
    size_ = capacity_ = bytes_ = 0;
  }
  void swap(PageArray& o) noexcept {
    std::swap(data_, o.data_);
    std::swap(size_, o.size_);
    std::swap(capacity_, o.capacity_);
    std::swap(bytes_, o.bytes_);
  }

  T* data_ = nullptr;
  std::size_t size_ = 0, capacity_ = 0, bytes_ = 0;
};

}  // namespace tetstream::core
