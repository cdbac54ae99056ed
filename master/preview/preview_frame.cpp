#include "master/preview/preview_frame.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#include "common/base/check.h"
#include "common/image/png_writer.h"

namespace raystack::master::preview {

FilmSnapshot TakeSnapshot(const render::Film& film, uint32_t frame) {
  FilmSnapshot s;
  s.width = film.width();
  s.height = film.height();
  s.frame = frame;
  film.ResolveColour(&s.rgb, &s.counts);
  for (uint32_t n : s.counts) s.samples_merged += n;
  return s;
}

Srgb8Encoder::Srgb8Encoder() {
  // Bisect over the bit patterns of non-negative floats (ordered like the floats themselves)
  // for the first value of each code: exact whatever the curve's rounding.
  for (int code = 1; code <= 255; ++code) {
    uint32_t lo = 0, hi = std::bit_cast<uint32_t>(1.0f);  // LinearToSrgb8(1) == 255
    while (lo < hi) {
      const uint32_t mid = lo + (hi - lo) / 2;
      if (image::LinearToSrgb8(std::bit_cast<float>(mid)) >= code) hi = mid;
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

void EncodeFrame(const FilmSnapshot& snapshot, float exposure, const Srgb8Encoder& encoder,
                 std::vector<uint8_t>* out) {
  const size_t pixels = static_cast<size_t>(snapshot.width) * static_cast<size_t>(snapshot.height);
  out->resize(kFrameHeaderBytes + 4 * pixels);
  const FrameHeader header{kFrameMagic, kFrameVersion, static_cast<uint32_t>(snapshot.width),
                           static_cast<uint32_t>(snapshot.height), snapshot.frame, exposure,
                           snapshot.samples_merged};
  std::memcpy(out->data(), &header, sizeof header);  // x86-64 and the page: little-endian
  const float scale = std::exp2(exposure);
  uint8_t* p = out->data() + kFrameHeaderBytes;
  for (size_t i = 0; i < pixels; ++i, p += 4) {
    const bool computed = snapshot.counts[i] > 0;
    for (size_t c = 0; c < 3; ++c) p[c] = computed ? encoder.Encode(snapshot.rgb[3 * i + c] * scale) : 0;
    p[3] = computed ? 255 : 0;
  }
}

}  // namespace raystack::master::preview
