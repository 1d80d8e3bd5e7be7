#pragma once
// Transparent huge pages for the large arrays that are accessed at random (the
// kernel's tets and coordinates, a segment's emitted tets): with 4 KiB pages nearly
// every access to a 100 MiB array misses the TLB, with 2 MiB pages almost none does.
// Advice only: where THP is off ("never") or unsupported this does nothing, and it
// changes no result.
#include <cstddef>
#include <cstdint>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace tetstream::core {

// Arrays below this are left to small pages: a huge page is resident whole once one
// byte of it is touched, and at the smallest budgets (a window of a few thousand
// points, --memory 32M) that rounding was megabytes of the budget for no TLB gain.
inline constexpr std::size_t kHugePageAdviceMin = std::size_t(8) << 20;

// Asks for huge pages on the 2 MiB-aligned part of [data, data + bytes) when bytes is
// at least kHugePageAdviceMin. Call it before the memory is first touched (the pages
// are chosen when they fault in).
inline void advise_huge_pages(const void* data, std::size_t bytes) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  if (bytes < kHugePageAdviceMin) return;
  constexpr std::uintptr_t kHuge = std::uintptr_t(1) << 21;
  const auto begin = (reinterpret_cast<std::uintptr_t>(data) + kHuge - 1) & ~(kHuge - 1);
  const auto end = (reinterpret_cast<std::uintptr_t>(data) + bytes) & ~(kHuge - 1);
  if (end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
#else
  (void)data, (void)bytes;
#endif
}

}  // namespace tetstream::core
