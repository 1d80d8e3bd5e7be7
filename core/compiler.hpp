#pragma once
// Compiler hints, in one place.
#if defined(__GNUC__) || defined(__clang__)
#define TS_FORCE_INLINE inline __attribute__((always_inline))
#define TS_NOINLINE __attribute__((noinline))
#define TS_LIKELY(x) __builtin_expect(!!(x), 1)
#define TS_UNLIKELY(x) __builtin_expect(!!(x), 0)
#define TS_PREFETCH(p) __builtin_prefetch(p)
#define TS_RESTRICT __restrict__
#else
#define TS_FORCE_INLINE inline
#define TS_NOINLINE
#define TS_LIKELY(x) (x)
#define TS_UNLIKELY(x) (x)
#define TS_PREFETCH(p)
#define TS_RESTRICT
#endif
