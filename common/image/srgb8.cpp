#include "common/image/srgb8.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>

#include "common/base/check.h"

namespace raystack::image {

uint8_t LinearToSrgb8(float linear) {
  if (!(linear > 0)) return 0;  // also NaN
  if (linear >= 1) return 255;
  const double v = linear <= 0.0031308f ? 12.92 * double{linear}
                                        : 1.055 * std::pow(double{linear}, 1.0 / 2.4) - 0.055;
  return static_cast<uint8_t>(v * 255.0 + 0.5);
}

Srgb8Encoder::Srgb8Encoder() {
  // Bisect over the bit patterns of non-negative floats (ordered like the floats themselves)
  // for the first value of each code: exact whatever the curve's rounding.
  for (int code = 1; code <= 255; ++code) {
    uint32_t lo = 0, hi = std::bit_cast<uint32_t>(1.0f);  // LinearToSrgb8(1) == 255
    while (lo < hi) {
      const uint32_t mid = lo + (hi - lo) / 2;
      if (LinearToSrgb8(std::bit_cast<float>(mid)) >= code) hi = mid;
      else lo = mid + 1;
    }
    lower_[static_cast<size_t>(code - 1)] = std::bit_cast<float>(lo);
  }
  lower_[255] = std::numeric_limits<float>::infinity();  // no code 256: stops the step below
  CHECK(lower_[0] > std::bit_cast<float>(kFirstBits));  // what is below the buckets is code 0
  for (size_t b = 0; b < kBuckets; ++b) {
    const float start = std::bit_cast<float>(kFirstBits + (static_cast<uint32_t>(b) << kBucketShift));
    bucket_code_[b] = static_cast<uint8_t>(std::upper_bound(lower_.begin(), lower_.begin() + 255, start) -
                                           lower_.begin());
  }
}

uint8_t Srgb8Encoder::Encode(float linear) const {
  if (!(linear > 0)) return 0;  // NaN and negatives, as LinearToSrgb8
  if (linear >= 1) return 255;
  const uint32_t bits = std::bit_cast<uint32_t>(linear);
  if (bits < kFirstBits) return 0;
  size_t code = bucket_code_[(bits - kFirstBits) >> kBucketShift];
  while (linear >= lower_[code]) ++code;  // lower_[code] is where code + 1 starts
  return static_cast<uint8_t>(code);
}

}  // namespace raystack::image
