#pragma once
// The spread-out pixel priority matrix (thesis Fig. VI.11): within every 16x16 square the
// pixels are ranked in Bayer (bit-reversed, interleaved) order, so the first pixels done are
// spread evenly over the whole frame and each later group halves the gaps. Higher is sooner.

#include <array>
#include <cstdint>

namespace raystack::render {

inline constexpr int kPriorityPeriod = 16;
inline constexpr uint16_t kMaxPixelPriority = kPriorityPeriod * kPriorityPeriod - 1;

// Bayer index of (x, y) in a 16x16 matrix: 0 for (0,0), then (8,8), (0,8), (8,0), (4,4)...
constexpr uint16_t BayerIndex16(int x, int y) {
  uint32_t v = 0;
  for (int bit = 3; bit >= 0; --bit) {
    const uint32_t xb = (static_cast<uint32_t>(x) >> bit) & 1u;
    const uint32_t yb = (static_cast<uint32_t>(y) >> bit) & 1u;
    // The coarsest level (bit 3) is the least significant digit: consecutive ranks jump
    // across the square first and fill the gaps later.
    v |= ((((xb ^ yb) << 1) | yb) << (2 * (3 - bit)));
  }
  return static_cast<uint16_t>(v);
}

// The pixel's rank in its 16x16 square: 0 is done first.
constexpr uint16_t PixelRank(int x, int y) {
  return BayerIndex16(x % kPriorityPeriod, y % kPriorityPeriod);
}

constexpr uint16_t PixelPriority(int x, int y) {
  return static_cast<uint16_t>(kMaxPixelPriority - PixelRank(x, y));
}

// Where each rank sits in the 16x16 square (PixelRank's inverse), so a tile's pixels can be
// listed rank by rank without sorting them.
struct RankPosition {
  uint8_t x, y;
};
inline constexpr std::array<RankPosition, kPriorityPeriod * kPriorityPeriod> kRankPositions = [] {
  std::array<RankPosition, kPriorityPeriod * kPriorityPeriod> p{};
  for (int y = 0; y < kPriorityPeriod; ++y)
    for (int x = 0; x < kPriorityPeriod; ++x)
      p[BayerIndex16(x, y)] = {static_cast<uint8_t>(x), static_cast<uint8_t>(y)};
  return p;
}();

}  // namespace raystack::render
