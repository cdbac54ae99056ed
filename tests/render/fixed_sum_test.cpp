// FixedSum rounds each value once to 2^-50 fixed point; values that fit in 64 bits take a
// fast path (multiply, 64-bit conversion) that must give the bits of the general one (ldexp,
// 128-bit conversion), or images would change with it.

#include "common/render/fixed_sum.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

namespace raystack::render {
namespace {

Int128 Reference(double x) {  // the general path alone
  constexpr double kLimit = 0x1p110;
  double scaled = std::ldexp(x, FixedSum::kFractionBits);
  if (!(scaled < kLimit)) scaled = scaled != scaled ? 0.0 : kLimit;
  if (scaled < -kLimit) scaled = -kLimit;
  return static_cast<Int128>(scaled);
}

TEST(FixedSum, FastPathGivesTheGeneralPathsBits) {
  std::vector<double> values = {0.0, -0.0, 1.0, -1.0, 0x1p-50, 0x1p-51, -0x1p-51, 0x1p-1074,
                                0x1p12, 0x1p12 - 0x1p-40, -0x1p12, 0x1p12 + 0x1p-40,
                                0x1p13, 1e23, -1e23, 1e300,
                                std::numeric_limits<double>::infinity(),
                                -std::numeric_limits<double>::infinity(),
                                std::numeric_limits<double>::quiet_NaN()};
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> mantissa(-1.0, 1.0);
  std::uniform_int_distribution<int> exponent(-60, 40);
  for (int i = 0; i < 200000; ++i) values.push_back(std::ldexp(mantissa(rng), exponent(rng)));
  for (double x : values) {
    ASSERT_TRUE(FixedSum::ToFixed(x) == Reference(x)) << x;
  }
}

// Values are clamped to +-kLargest, so kMaxTerms of the largest, either sign, still sum
// exactly (no wrap-around) and can be taken back out.
TEST(FixedSum, TheLargestSumsDoNotWrap) {
  FixedSum high, low;
  for (uint64_t i = 0; i < FixedSum::kMaxTerms; ++i) {
    high.Add(1e300);
    low.Add(-1e300);
  }
  EXPECT_EQ(high.Value(), FixedSum::kLargest * static_cast<double>(FixedSum::kMaxTerms));
  EXPECT_EQ(low.Value(), -FixedSum::kLargest * static_cast<double>(FixedSum::kMaxTerms));
  FixedSum bright;  // a pixel of emission 1e21 at 4096 samples: clamped, never negative
  for (int i = 0; i < 4096; ++i) bright.Add(1e21);
  EXPECT_EQ(bright.Value(), FixedSum::kLargest * 4096);
  for (uint64_t i = 0; i < FixedSum::kMaxTerms; ++i) high.Subtract(1e300);
  EXPECT_TRUE(high.raw() == 0);
}

TEST(FixedSum, SumsDoNotDependOnOrder) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-100.0, 100.0);
  std::vector<double> v(10000);
  for (double& x : v) x = u(rng) * u(rng);
  FixedSum forward, backward;
  for (double x : v) forward.Add(x);
  for (auto it = v.rbegin(); it != v.rend(); ++it) backward.Add(*it);
  EXPECT_TRUE(forward.raw() == backward.raw());
  for (double x : v) forward.Subtract(x);
  EXPECT_TRUE(forward.raw() == 0);
}

}  // namespace
}  // namespace raystack::render
