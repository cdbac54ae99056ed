#pragma once
// Small fixed-size vectors for geometry. Plain aggregates: trivially copyable, no padding.

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace raystack {

struct Vec3f {
  float x = 0, y = 0, z = 0;

  constexpr float operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
  constexpr float& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
};
static_assert(sizeof(Vec3f) == 12);

constexpr Vec3f operator+(Vec3f a, Vec3f b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
constexpr Vec3f operator-(Vec3f a, Vec3f b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
constexpr Vec3f operator-(Vec3f a) { return {-a.x, -a.y, -a.z}; }
constexpr Vec3f operator*(Vec3f a, float s) { return {a.x * s, a.y * s, a.z * s}; }
constexpr Vec3f operator*(float s, Vec3f a) { return a * s; }
constexpr Vec3f operator*(Vec3f a, Vec3f b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
constexpr bool operator==(Vec3f a, Vec3f b) { return a.x == b.x && a.y == b.y && a.z == b.z; }

constexpr float Dot(Vec3f a, Vec3f b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
constexpr Vec3f Cross(Vec3f a, Vec3f b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline float Length(Vec3f a) { return std::sqrt(Dot(a, a)); }
inline Vec3f Normalize(Vec3f a) { return a * (1.0f / Length(a)); }
// `a` times the power of two that brings its largest component into [0.5, 1) when it lies
// outside [2^-30, 2^30]: the same direction, bit for bit the same after Normalize (a power of
// two scales exactly), but a vector whose squared length (or, for an edge, its cross
// product's squared length: the 4th power) would overflow or underflow float can now be
// normalised. Inside that range (every ordinary scene) it costs one comparison. Zero, infinite
// and NaN vectors come back as they are.
inline Vec3f ScaledToUnitRange(Vec3f a) {
  const float m = std::max(std::fabs(a.x), std::max(std::fabs(a.y), std::fabs(a.z)));
  if ((m >= 0x1p-30f && m <= 0x1p30f) || !(m > 0) || !std::isfinite(m)) return a;
  int e = 0;
  std::frexp(m, &e);
  return {std::ldexp(a.x, -e), std::ldexp(a.y, -e), std::ldexp(a.z, -e)};
}
inline Vec3f Min(Vec3f a, Vec3f b) {
  return {std::min(a.x, b.x), std::min(a.y, b.y), std::min(a.z, b.z)};
}
inline Vec3f Max(Vec3f a, Vec3f b) {
  return {std::max(a.x, b.x), std::max(a.y, b.y), std::max(a.z, b.z)};
}
inline bool IsFinite(Vec3f a) {
  return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z);
}

}  // namespace raystack
