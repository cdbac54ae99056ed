#pragma once
// Per-pixel deterministic random numbers: every number a sample uses is a hash of (seed,
// pixel, sample, bounce, dimension), so a ray needs no generator state and the image does not
// depend on which thread, rank or mode traced which ray, nor on the order.

#include <cstdint>

namespace raystack::render {

inline uint64_t MixBits(uint64_t v) {  // splitmix64 finaliser
  v ^= v >> 30;
  v *= 0xbf58476d1ce4e5b9ull;
  v ^= v >> 27;
  v *= 0x94d049bb133111ebull;
  v ^= v >> 31;
  return v;
}

// What a random number is for, so two uses at one bounce never share a value.
enum class RandomUse : uint32_t {
  kPixelJitterX = 0, kPixelJitterY, kLightChoice, kBsdfU, kBsdfV, kLobe, kRoulette,
  kEmitterChoice, kEmitterU, kEmitterV, kEmitterChoiceLow, kLightChoiceLow
};

class SampleRandom {
 public:
  SampleRandom(uint64_t seed, uint32_t pixel, uint32_t sample)
      : base_(MixBits(seed ^ MixBits((uint64_t{pixel} << 20) ^ sample ^ 0x9e3779b97f4a7c15ull))) {}

  // Uniform in [0, 1): 24 random bits, so the value is exact in a float and never 1.
  float Uniform(uint32_t bounce, RandomUse use) const {
    const uint64_t h = MixBits(base_ ^ MixBits((uint64_t{bounce} << 8) | static_cast<uint32_t>(use)));
    return static_cast<float>(h >> 40) * 0x1p-24f;
  }

 private:
  uint64_t base_;
};

}  // namespace raystack::render
