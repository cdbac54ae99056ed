// The inline NextUp and NextDown are std::nextafter towards +inf and -inf, bit for bit.

#include "common/geometry/next_float.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>

namespace raystack {
namespace {

TEST(NextFloat, IsNextafterTowardsEitherInfinity) {
  const float inf = std::numeric_limits<float>::infinity();
  for (float x : {0.0f, -0.0f, 1.0f, -1.0f, 3.5e-30f, -3.5e-30f, 1e38f, -1e38f,
                  std::numeric_limits<float>::denorm_min(), -std::numeric_limits<float>::denorm_min(),
                  std::numeric_limits<float>::min(), -std::numeric_limits<float>::min(),
                  std::numeric_limits<float>::max(), -std::numeric_limits<float>::max(), inf, -inf}) {
    const float up = NextUp(x), up_libm = std::nextafter(x, inf);
    const float down = NextDown(x), down_libm = std::nextafter(x, -inf);
    EXPECT_EQ(std::memcmp(&up, &up_libm, sizeof(float)), 0) << x;
    EXPECT_EQ(std::memcmp(&down, &down_libm, sizeof(float)), 0) << x;
  }
  EXPECT_TRUE(std::isnan(NextUp(std::numeric_limits<float>::quiet_NaN())));
  EXPECT_TRUE(std::isnan(NextDown(std::numeric_limits<float>::quiet_NaN())));
}

}  // namespace
}  // namespace raystack
