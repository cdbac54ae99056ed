#pragma once
// Order-independent sums of floats. Rays of one sample, and samples of one pixel, finish in an
// order that depends on block loads, threads and (later) ranks; float addition is not
// associative, so summing in completion order would make images differ in the last bit between
// modes. Each value is instead rounded once, on its own, to a 128-bit fixed-point number, and
// integer addition is exact and associative: any order gives the same bits.

#include <cmath>
#include <cstdint>

namespace raystack::render {

__extension__ typedef __int128 Int128;

class FixedSum {
 public:
  // 2^-50 resolution (~9e-16). Each value is clamped to +-2^60 (~1.2e18) as it is rounded,
  // so that the sum of kMaxTerms of them stays inside 128 bits: a sum that wrapped around
  // turned a pixel of extreme radiance (emission 1e21 at 4096 samples) negative. Radiance of
  // 1e-6 to 1e12 is exact to the resolution; its squares (for variances) clamp from ~1e9 on.
  static constexpr int kFractionBits = 50;  // Value() scales by 0x1p-50 to match
  static_assert(kFractionBits == 50, "ToFixed and Value scale by the literal 2^50");
  static constexpr double kLargest = 0x1p60;  // |value| rounded at most to this
  static constexpr uint64_t kMaxTerms = uint64_t{1} << 16;  // values a sum may hold

  // Adds x (a finite value; callers drop non-finite ones and count them).
  void Add(double x) { value_ += ToFixed(x); }
  void Add(const FixedSum& other) { value_ += other.value_; }
  // Takes back an Add(x) exactly (integers): the sum is as if x had never been added.
  void Subtract(double x) { value_ -= ToFixed(x); }
  double Value() const {
    // Most sums fit in 64 bits, whose conversion is one instruction (the 128-bit one is a
    // library call): both round the same integer the same way. Scaling by a power of two is
    // exact, as ldexp.
    const int64_t low = static_cast<int64_t>(value_);
    const double v = static_cast<Int128>(low) == value_ ? static_cast<double>(low)
                                                        : static_cast<double>(value_);
    return v * 0x1p-50;
  }
  Int128 raw() const { return value_; }

  static Int128 ToFixed(double x) {
    // Scaling by a power of two is exact (as ldexp, a library call, would be); a value that
    // fits in 64 bits converts in one instruction and truncates as the 128-bit conversion
    // (another library call: with ldexp, 3% of a ray thread's time in the profile) would.
    double scaled = x * 0x1p50;  // 2^kFractionBits
    if (scaled > -0x1p62 && scaled < 0x1p62) return static_cast<int64_t>(scaled);
    constexpr double kLimit = 0x1p110;  // kLargest * 2^50: kMaxTerms (2^16) of them < 2^127
    if (!(scaled < kLimit)) scaled = scaled != scaled ? 0.0 : kLimit;
    if (scaled < -kLimit) scaled = -kLimit;
    return static_cast<Int128>(scaled);
  }

 private:
  Int128 value_ = 0;
};

}  // namespace raystack::render
