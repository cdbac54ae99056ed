#pragma once
// Linear radiance to 8-bit sRGB codes, as the PNG quick look and the live preview show them
// (the page and the PNG agree to the bit).

#include <array>
#include <cstddef>
#include <cstdint>

namespace raystack::image {

// The 8-bit sRGB code of a linear value (clamped to [0, 1]; NaN -> 0), the reference
// (a pow per call) that Srgb8Encoder reproduces.
uint8_t LinearToSrgb8(float linear);

// 8-bit sRGB codes of linear values, equal to LinearToSrgb8 for every float, without
// a pow per channel: a table indexed by the float's exponent and top mantissa bits gives the
// code at the start of the value's bucket, and at most a step or two over the exact code
// boundaries finishes it.
class Srgb8Encoder {
 public:
  Srgb8Encoder();
  uint8_t Encode(float linear) const;

 private:
  // Buckets cover [2^-13, 1) (below, every value is code 0), 2^8 per power of two.
  static constexpr uint32_t kFirstBits = 0x39000000;  // the bits of 2^-13
  static constexpr int kBucketShift = 23 - 8;
  static constexpr size_t kBuckets = (0x3f800000 - kFirstBits) >> kBucketShift;
  std::array<float, 256> lower_;  // lower_[c-1]: the smallest value that encodes to c; [255] = inf
  std::array<uint8_t, kBuckets> bucket_code_;  // the code of each bucket's smallest value
};

}  // namespace raystack::image
