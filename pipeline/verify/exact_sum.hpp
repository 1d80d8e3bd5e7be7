#pragma once
// An exact sum of long doubles (a fixed-point accumulator over the whole long double
// range): verify's volumes. Why exact: a rounded sum depends on the order of its terms,
// and verify's terms arrive in an order that depends on how the work was cut (threads,
// spills, the ranks of a distributed job); the exact sum does not, so every cut reports
// the same volumes, to the last bit, and two partial sums merge without a rounding.
//
// Representation: value = sum over i of limb[i] * 2^(32 i + kLow). A term's 64-bit
// significand shifted into place covers at most three limbs; each limb receives less
// than 2^32 in magnitude a term, so int64 limbs take 2^30 terms before carries must be
// propagated (normalize(), done then and before reading).
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

namespace tetstream::pipeline::verify_engine {

// det3 and a bound on the distance from the computed value to the exact determinant
// of the four points. Rounding analysis (Shewchuk's orient3d): with u the unit
// roundoff of T, |computed - exact| <= (7u + 56u^2) * permanent, the permanent
// being the same expression with absolute values over the computed differences; 16u
// covers that and the rounding of the permanent itself. No product underflows or
// overflows in T (volume_fits_double), so the bound holds without an absolute term;
// one of T's smallest subnormals is added anyway for the float32 path's exact zeros.
template <class T>
struct BoundedDet {
  T value, error;
};
template <class T>
inline BoundedDet<T> det3_bounded(const double* a, const double* b, const double* c, const double* d) {
  const T bx = T(b[0]) - a[0], by = T(b[1]) - a[1], bz = T(b[2]) - a[2];
  const T cx = T(c[0]) - a[0], cy = T(c[1]) - a[1], cz = T(c[2]) - a[2];
  const T dx = T(d[0]) - a[0], dy = T(d[1]) - a[1], dz = T(d[2]) - a[2];
  const T value = bx * (cy * dz - cz * dy) - by * (cx * dz - cz * dx) + bz * (cx * dy - cy * dx);
  using std::fabs;
  const T permanent = fabs(bx) * (fabs(cy * dz) + fabs(cz * dy)) + fabs(by) * (fabs(cx * dz) + fabs(cz * dx)) +
                      fabs(bz) * (fabs(cx * dy) + fabs(cy * dx));
  constexpr T u = std::numeric_limits<T>::epsilon() / 2;
  return {value, permanent * (16 * u) + std::numeric_limits<T>::denorm_min()};
}

class ExactSum {
 public:
  // Every finite long double is a multiple of 2^kLow (below the smallest subnormal's
  // exponent, rounded down to a limb) and below 2^kHigh.
  static constexpr int kLow = -16512;
  static constexpr int kHigh = 16448;
  static constexpr std::size_t kLimbs = std::size_t(kHigh - kLow) / 32 + 4;
  static_assert(std::numeric_limits<long double>::digits <= 64, "a term's significand must fit 64 bits");
  static_assert(std::numeric_limits<long double>::min_exponent - std::numeric_limits<long double>::digits >= kLow,
                "the accumulator must reach the smallest subnormal");
  static_assert(std::numeric_limits<long double>::max_exponent <= kHigh,
                "the accumulator must reach the largest value");

  ExactSum() : limb_(kLimbs, 0) {}

  // Non-finite terms make the sum non-finite (they are kept aside, not accumulated).
  void add(long double x) {
    if (x == 0) return;
    if (const double d = double(x); d == x) return add(d);  // the common case, without frexpl
    if (!std::isfinite(x)) {
      special_ += x;
      return;
    }
    int e = 0;
    const long double m = std::frexp(std::fabs(x), &e);          // |x| = m * 2^e, m in [0.5, 1)
    const std::uint64_t sig = std::uint64_t(std::ldexp(m, 64));  // exact: m has at most 64 bits
    place(sig, e - 64 - kLow, x < 0);                            // |x| = sig * 2^(e - 64)
  }

  void add(double x) {
    const std::uint64_t bits = std::bit_cast<std::uint64_t>(x);
    const int field = int(bits >> 52 & 0x7FF);
    if (field == 0x7FF) {
      special_ += x;
      return;
    }
    std::uint64_t sig = bits & ((std::uint64_t(1) << 52) - 1);
    if (field) sig |= std::uint64_t(1) << 52;
    if (sig == 0) return;
    // |x| = sig * 2^(max(field, 1) - 1075).
    place(sig, (field ? field : 1) - 1075 - kLow, (bits >> 63) != 0);
  }

  void add(const ExactSum& o) {
    ExactSum b = o;
    b.normalize();
    normalize();
    for (std::size_t i = 0; i < kLimbs; ++i) limb_[i] += b.limb_[i];
    special_ += b.special_;
    pending_ = 1;
    normalize();
  }

  // Subtracts another sum, exactly.
  void subtract(const ExactSum& o) {
    ExactSum b = o;
    b.normalize();
    normalize();
    for (std::size_t i = 0; i < kLimbs; ++i) limb_[i] -= b.limb_[i];
    special_ -= b.special_;
    pending_ = 1;
    normalize();
  }

  // The sum, rounded towards zero to a long double (a function of the exact sum alone).
  long double value() const {
    ExactSum c = *this;
    c.normalize();
    if (c.special_ != 0 || c.special_ != c.special_) return c.special_;  // an inf or a NaN term
    // After normalize, limbs 0..kLimbs-2 are in [0, 2^32) and the top limb carries the
    // sign (the number is in two's complement over the limbs): negate when negative.
    const bool negative = c.limb_.back() < 0;
    if (negative) {
      std::int64_t carry = 0;
      for (auto& l : c.limb_) {
        const std::int64_t v = -l + carry;
        l = v & 0xFFFFFFFF;
        carry = (v - l) >> 32;
      }
    }
    std::size_t h = kLimbs;
    while (h > 0 && c.limb_[h - 1] == 0) --h;
    if (h == 0) return 0;
    // The top 96 bits: the first two limbs add exactly, the third rounds at most once;
    // what lies below them is dropped.
    long double v = 0;
    for (std::size_t k = 0; k < 3 && h >= k + 1; ++k) {
      const std::size_t i = h - 1 - k;
      v += std::ldexp(static_cast<long double>(c.limb_[i]), int(32 * i) + kLow);
    }
    return negative ? -v : v;
  }

  // Limbs as bytes and back (a rank's partial sum sent to rank 0).
  std::string bytes() const {
    ExactSum c = *this;
    c.normalize();
    std::string out(reinterpret_cast<const char*>(c.limb_.data()), kLimbs * sizeof(std::int64_t));
    out.append(reinterpret_cast<const char*>(&c.special_), sizeof c.special_);
    return out;
  }
  static ExactSum from_bytes(const std::string& b) {
    ExactSum s;
    if (b.size() != kLimbs * sizeof(std::int64_t) + sizeof(long double)) return s;
    std::memcpy(s.limb_.data(), b.data(), kLimbs * sizeof(std::int64_t));
    std::memcpy(&s.special_, b.data() + kLimbs * sizeof(std::int64_t), sizeof s.special_);
    return s;
  }

 private:
  // Adds (negative ? -1 : 1) * sig * 2^(p + kLow), p >= 0.
  void place(std::uint64_t sig, int p, bool negative) {
    const std::size_t i = std::size_t(p / 32);
    const unsigned __int128 t = static_cast<unsigned __int128>(sig) << (p % 32);
    const std::int64_t s = negative ? -1 : 1;
    limb_[i] += s * std::int64_t(std::uint64_t(t) & 0xFFFFFFFFu);
    limb_[i + 1] += s * std::int64_t(std::uint64_t(t >> 32) & 0xFFFFFFFFu);
    limb_[i + 2] += s * std::int64_t(std::uint64_t(t >> 64));
    if (++pending_ == (std::uint64_t(1) << 30)) normalize();
  }

  // Carries up: every limb but the top one into [0, 2^32).
  void normalize() {
    std::int64_t carry = 0;
    for (std::size_t i = 0; i + 1 < kLimbs; ++i) {
      const std::int64_t v = limb_[i] + carry;
      limb_[i] = v & 0xFFFFFFFF;
      carry = (v - limb_[i]) >> 32;
    }
    limb_.back() += carry;
    pending_ = 0;
  }

  std::vector<std::int64_t> limb_;
  long double special_ = 0;  // the sum of the non-finite terms
  std::uint64_t pending_ = 0;
};

}  // namespace tetstream::pipeline::verify_engine
