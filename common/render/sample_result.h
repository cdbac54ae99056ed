#pragma once
// What a slave produces and the master merges: one finished sample of one pixel. Plain data,
// so it can cross threads now and ranks later without translation.

#include <cstdint>
#include <span>

namespace raystack::render {

struct SampleResult {
  uint32_t pixel;      // y * width + x
  uint32_t sample;     // index of the sample within the pixel
  float rgb[3];        // the sample's radiance (already summed order-independently)
  // Primary-hit data, meaningful for sample 0 only (the pixel-centre ray at one sample per
  // pixel, jittered as the others with more): distance along the
  // primary ray (+inf on a miss), shading normal facing the camera, albedo of the material.
  float z;
  float normal[3];
  float albedo[3];
  uint32_t hit;        // 1 when the primary ray hit geometry (alpha coverage)
};
static_assert(sizeof(SampleResult) == 52);

// Receives finished samples in batches. Called from ray threads (concurrently: implementations
// synchronise); coarse grain, one virtual call per batch.
class SampleSink {
 public:
  virtual ~SampleSink() = default;
  // `rays`: how many rays the thread traced since its last batch (progress figures).
  virtual void Consume(std::span<const SampleResult> batch, uint64_t rays) = 0;
};

}  // namespace raystack::render
