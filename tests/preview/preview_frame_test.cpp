#include "master/preview/preview_frame.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#include "common/image/srgb8.h"

namespace raystack::master::preview {
namespace {

render::SampleResult Sample(uint32_t pixel, uint32_t index, float r, float g, float b) {
  render::SampleResult s{};
  s.pixel = pixel;
  s.sample = index;
  s.rgb[0] = r, s.rgb[1] = g, s.rgb[2] = b;
  s.z = 1;
  s.hit = 1;
  return s;
}

// The largest frame streamed is 4096 x 4096 pixels, whatever its shape; past it the page says
// so (LivePreview::BeginFrame) and shows the progress only.
TEST(Streamed, UpTo4096By4096PixelsWhateverTheShape) {
  EXPECT_TRUE(Streamed(4096, 4096));
  EXPECT_TRUE(Streamed(16384, 1024));
  EXPECT_FALSE(Streamed(4097, 4096));
  EXPECT_FALSE(Streamed(65536, 257));
  EXPECT_FALSE(Streamed(1 << 30, 1 << 30));  // no overflow
}

TEST(Srgb8Encoder, EqualsThePngToneMapForEveryCodeBoundaryAndASweep) {
  const Srgb8Encoder encoder;
  // Every 4099th float from 0 to 1.5, every 257th from 2^-13 to 1 (where the table is).
  for (uint32_t bits = 0; bits <= std::bit_cast<uint32_t>(1.5f); bits += 4099) {
    const float v = std::bit_cast<float>(bits);
    ASSERT_EQ(encoder.Encode(v), image::LinearToSrgb8(v)) << v;
  }
  for (uint32_t bits = std::bit_cast<uint32_t>(0x1p-13f); bits < std::bit_cast<uint32_t>(1.0f); bits += 257) {
    const float v = std::bit_cast<float>(bits);
    ASSERT_EQ(encoder.Encode(v), image::LinearToSrgb8(v)) << v;
  }
  for (float v : {0.0f, -0.0f, -1.0f, 1.0f, 0.0031308f, std::numeric_limits<float>::infinity(),
                  std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::denorm_min()})
    EXPECT_EQ(encoder.Encode(v), image::LinearToSrgb8(v)) << v;
  // Each code's first value (found here by bisection on the PNG's function) and its
  // neighbours, to the last bit.
  for (int code = 1; code < 256; ++code) {
    uint32_t lo = 0, hi = std::bit_cast<uint32_t>(1.0f);
    while (lo < hi) {
      const uint32_t mid = lo + (hi - lo) / 2;
      if (image::LinearToSrgb8(std::bit_cast<float>(mid)) >= code) hi = mid;
      else lo = mid + 1;
    }
    for (uint32_t bits = lo - 2; bits <= lo + 2; ++bits) {
      const float v = std::bit_cast<float>(bits);
      ASSERT_EQ(encoder.Encode(v), image::LinearToSrgb8(v)) << "code " << code << ", " << v;
    }
  }
}

// The preview's light copy (Film::ResolveColour) gives the very bits of Film::Resolve, so the
// page shows what the EXR and PNG hold.
TEST(TakeSnapshot, HasTheBitsOfResolve) {
  render::Film film(17, 9);
  std::vector<render::SampleResult> batch;
  uint32_t state = 12345;
  auto next = [&] { return (state = state * 1664525u + 1013904223u) >> 8; };
  for (uint32_t k = 0; k < 400; ++k) {
    const uint32_t pixel = next() % (17 * 9 - 5);  // the last 5 pixels get nothing
    batch.push_back(Sample(pixel, k, static_cast<float>(next() % 1000) / 333.0f,
                           static_cast<float>(next() % 1000) / 77.0f, static_cast<float>(next() % 7)));
  }
  film.Merge(batch);
  const image::ImageLayers layers = film.Resolve();
  std::chrono::steady_clock::duration held{-1};  // how long the film's lock was held: set
  const FilmSnapshot s = TakeSnapshot(film, 0, &held);
  EXPECT_GE(held.count(), 0);
  ASSERT_EQ(s.counts, layers.samples);
  EXPECT_EQ(s.samples_merged, 400u);
  for (size_t i = 0; i < layers.pixel_count(); ++i)
    for (size_t c = 0; c < 3; ++c)
      ASSERT_EQ(std::bit_cast<uint32_t>(s.rgb[3 * i + c]), std::bit_cast<uint32_t>(layers.rgba[4 * i + c])) << i;
}

// --resume: the pixels a checkpoint held finished are shown as it has them (they were shown as
// not computed, and the page's progress stopped short of 100%).
TEST(TakeSnapshot, ShowsAResumedRunsRestoredPixels) {
  render::Film before(5, 3);
  std::vector<render::SampleResult> batch;
  for (uint32_t k = 0; k < 4; ++k) batch.push_back(Sample(k % 2, k, 0.25f * k, 1.0f, 2.0f));
  before.Merge(batch);
  const image::ImageLayers checkpoint = before.Resolve();  // pixels 0 and 1: 2 samples each
  render::Film film(5, 3);
  const uint32_t restored[] = {0, 1};
  film.Restore(checkpoint, restored);
  const render::SampleResult fresh[] = {Sample(7, 0, 3.0f, 3.0f, 3.0f)};
  film.Merge(fresh);
  EXPECT_EQ(film.samples_restored(), 4u);
  const image::ImageLayers layers = film.Resolve();
  const FilmSnapshot s = TakeSnapshot(film, 0);
  ASSERT_EQ(s.counts, layers.samples);
  EXPECT_EQ(s.counts[0], 2u);
  EXPECT_EQ(s.counts[7], 1u);
  EXPECT_EQ(s.samples_merged, 5u);
  for (size_t i = 0; i < layers.pixel_count(); ++i)
    for (size_t c = 0; c < 3; ++c)
      ASSERT_EQ(std::bit_cast<uint32_t>(s.rgb[3 * i + c]), std::bit_cast<uint32_t>(layers.rgba[4 * i + c])) << i;
}

TEST(EncodeFrame, HeaderThenToneMappedPixelsWithComputedInAlpha) {
  render::Film film(3, 2);
  const render::SampleResult samples[] = {Sample(0, 0, 0.5f, 0.25f, 2.0f), Sample(0, 1, 0.5f, 0.25f, 0.0f),
                                          Sample(4, 0, 0.1f, 0.2f, 0.3f)};
  film.Merge(samples);
  const FilmSnapshot snapshot = TakeSnapshot(film, 7);
  EXPECT_EQ(snapshot.samples_merged, 3u);
  std::vector<uint8_t> bytes;
  EncodeFrame(snapshot, 1.0f, Srgb8Encoder(), &bytes);
  ASSERT_EQ(bytes.size(), kFrameHeaderBytes + 4 * 6);
  FrameHeader h;
  std::memcpy(&h, bytes.data(), sizeof h);
  EXPECT_EQ(h.magic, kFrameMagic);
  EXPECT_EQ(h.version, kFrameVersion);
  EXPECT_EQ(h.width, 3u);
  EXPECT_EQ(h.height, 2u);
  EXPECT_EQ(h.frame, 7u);
  EXPECT_EQ(h.exposure, 1.0f);
  EXPECT_EQ(h.samples_merged, 3u);
  const uint8_t* p = bytes.data() + kFrameHeaderBytes;
  // Pixel 0: mean (0.5, 0.25, 1.0), times 2^1.
  EXPECT_EQ(p[0], image::LinearToSrgb8(1.0f));
  EXPECT_EQ(p[1], image::LinearToSrgb8(0.5f));
  EXPECT_EQ(p[2], 255);
  EXPECT_EQ(p[3], 255);
  // Pixel 4 = (1, 1).
  EXPECT_EQ(p[16 + 0], image::LinearToSrgb8(0.2f));
  EXPECT_EQ(p[16 + 2], image::LinearToSrgb8(0.6f));
  EXPECT_EQ(p[16 + 3], 255);
  // The others are not computed: transparent black, for the page to fill.
  for (int i : {1, 2, 3, 5})
    for (int c = 0; c < 4; ++c) EXPECT_EQ(p[4 * i + c], 0) << i;
}

}  // namespace
}  // namespace raystack::master::preview
