#pragma once
// std::nextafter(x, +inf) and (x, -inf) for floats, inline: libm's is a call, and the
// traversal (once per hit) and the converter's clipping (per clipped triangle) are hot paths.

#include <cstdint>
#include <cstring>
#include <limits>

namespace raystack {

inline float NextUp(float x) {
  if (!(x < std::numeric_limits<float>::infinity())) return x;  // +inf and NaN
  if (x == 0.0f) return std::numeric_limits<float>::denorm_min();
  uint32_t bits;
  std::memcpy(&bits, &x, sizeof(bits));
  bits = x > 0 ? bits + 1 : bits - 1;  // the magnitude grows for x > 0, shrinks for x < 0
  std::memcpy(&x, &bits, sizeof(bits));
  return x;
}

inline float NextDown(float x) { return -NextUp(-x); }

}  // namespace raystack
