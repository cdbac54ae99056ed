// ClipTriangleToCell must be conservative (its box holds every point of triangle ∩ cell and
// never drops a triangle that touches the cell) and must stay inside the cell.

#include "tools/prep/clip.h"

#include <gtest/gtest.h>

#include <random>

namespace raystack::prep {
namespace {

struct Point {
  double v[3];
};

// A point of the triangle from barycentric weights, in double (the exact triangle).
Point OnTriangle(const Vec3f p[3], double u, double v) {
  const double w = 1.0 - u - v;
  Point q;
  for (int k = 0; k < 3; ++k)
    q.v[k] = w * double{p[0][k]} + u * double{p[1][k]} + v * double{p[2][k]};
  return q;
}

bool InCell(const Point& q, const Bounds3f& cell) {
  for (int k = 0; k < 3; ++k)
    if (q.v[k] < double{cell.lower[k]} || q.v[k] > double{cell.upper[k]}) return false;
  return true;
}

bool InBox(const Point& q, const Bounds3f& box) {
  for (int k = 0; k < 3; ++k)
    if (q.v[k] < double{box.lower[k]} || q.v[k] > double{box.upper[k]}) return false;
  return true;
}

Bounds3f BoxOf(const Vec3f p[3]) {
  Bounds3f b;
  for (int i = 0; i < 3; ++i) b.Extend(p[i]);
  return b;
}

// For random triangles around `cell`: every sampled point of the triangle inside the cell is
// in the clipped box, and the box lies inside the cell and inside the triangle's own box.
// Returns how many triangles crossed the cell boundary (so callers can check the case was hit).
int CheckRandomTriangles(const Bounds3f& cell, uint64_t seed) {
  std::mt19937_64 rng(seed);
  const Vec3f e = cell.Extent();
  std::uniform_real_distribution<float> coord(-1.0f, 2.0f);  // in units of the cell's size
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  int crossing = 0;
  for (int t = 0; t < 2000; ++t) {
    Vec3f p[3];
    for (Vec3f& v : p)
      v = {cell.lower.x + e.x * coord(rng), cell.lower.y + e.y * coord(rng),
           cell.lower.z + e.z * coord(rng)};
    const Bounds3f box = ClipTriangleToCell(p, cell);
    int inside_samples = 0;
    for (int s = 0; s < 400; ++s) {
      double u = unit(rng), v = unit(rng);
      if (u + v > 1) {
        u = 1 - u;
        v = 1 - v;
      }
      const Point q = OnTriangle(p, u, v);
      if (!InCell(q, cell)) continue;
      ++inside_samples;
      EXPECT_TRUE(InBox(q, box)) << "triangle " << t << " sample (" << q.v[0] << ", " << q.v[1]
                                 << ", " << q.v[2] << ") is in the cell but not in the box";
    }
    if (box.Empty()) {
      EXPECT_EQ(inside_samples, 0) << "triangle " << t << " meets the cell but was dropped";
      continue;
    }
    EXPECT_TRUE(cell.Contains(box)) << "triangle " << t << ": box leaves the cell";
    EXPECT_TRUE(BoxOf(p).Contains(box)) << "triangle " << t << ": box leaves the triangle's box";
    if (!cell.Contains(BoxOf(p)) && inside_samples > 0) ++crossing;
  }
  return crossing;
}

TEST(ClipTriangleToCell, InsideGivesTheTrianglesBox) {
  const Bounds3f cell{{0, 0, 0}, {1, 1, 1}};
  const Vec3f p[3] = {{0.1f, 0.2f, 0.3f}, {0.9f, 0.25f, 0.4f}, {0.5f, 0.8f, 0.7f}};
  const Bounds3f box = ClipTriangleToCell(p, cell);
  const Bounds3f expected = BoxOf(p);
  EXPECT_EQ(box.lower, expected.lower);
  EXPECT_EQ(box.upper, expected.upper);
}

TEST(ClipTriangleToCell, OutsideGivesAnEmptyBox) {
  const Bounds3f cell{{0, 0, 0}, {1, 1, 1}};
  const Vec3f beside[3] = {{1.5f, 0.2f, 0.3f}, {2.5f, 0.25f, 0.4f}, {1.7f, 0.8f, 0.7f}};
  EXPECT_TRUE(ClipTriangleToCell(beside, cell).Empty());
  // Its box overlaps the cell but the triangle passes by the corner.
  const Vec3f by_corner[3] = {{0.9f, 1.5f, 0.5f}, {1.5f, 0.9f, 0.5f}, {1.5f, 1.5f, 0.5f}};
  ASSERT_TRUE(BoxOf(by_corner).Overlaps(cell));
  EXPECT_TRUE(ClipTriangleToCell(by_corner, cell).Empty());
}

TEST(ClipTriangleToCell, CrossingBoxHoldsEveryPointInTheCell) {
  const Bounds3f cell{{0, 0, 0}, {1, 1, 1}};
  EXPECT_GT(CheckRandomTriangles(cell, 1), 100);
}

TEST(ClipTriangleToCell, CrossingBoxIsTighterThanTheTrianglesBox) {
  // A long thin diagonal triangle through a small cell: the clipped box is the cell's part.
  const Bounds3f cell{{0, 0, 0}, {1, 1, 1}};
  const Vec3f p[3] = {{-10, -10, 0.5f}, {11, 11, 0.5f}, {11, 11.1f, 0.5f}};
  const Bounds3f box = ClipTriangleToCell(p, cell);
  ASSERT_FALSE(box.Empty());
  EXPECT_TRUE(cell.Contains(box));
  EXPECT_EQ(box.lower.z, 0.5f);
  EXPECT_EQ(box.upper.z, 0.5f);
}

TEST(ClipTriangleToCell, TriangleOnACellFaceIsKept) {
  const Bounds3f cell{{0, 0, 0}, {1, 1, 1}};
  for (int axis = 0; axis < 3; ++axis) {
    for (float plane : {0.0f, 1.0f}) {
      Vec3f p[3] = {{0.2f, 0.2f, 0.2f}, {0.8f, 0.3f, 0.6f}, {0.4f, 0.9f, 0.7f}};
      for (Vec3f& v : p) v[axis] = plane;
      const Bounds3f box = ClipTriangleToCell(p, cell);
      ASSERT_FALSE(box.Empty()) << "axis " << axis << " plane " << plane;
      EXPECT_EQ(box.lower[axis], plane);
      EXPECT_EQ(box.upper[axis], plane);
    }
  }
  // Sticking out of a face (half in the cell, half in the neighbour) and lying on another.
  const Vec3f out[3] = {{0.5f, 0.5f, 1.0f}, {1.5f, 0.5f, 1.0f}, {1.5f, 0.9f, 1.0f}};
  const Bounds3f box = ClipTriangleToCell(out, cell);
  ASSERT_FALSE(box.Empty());
  EXPECT_EQ(box.upper.x, 1.0f);
  EXPECT_EQ(box.lower.z, 1.0f);
}

TEST(ClipTriangleToCell, TriangleTouchingTheCellFromOutsideIsKept) {
  const Bounds3f cell{{0, 0, 0}, {1, 1, 1}};
  // One vertex exactly on the face x = 1, the rest outside.
  const Vec3f p[3] = {{1.0f, 0.5f, 0.5f}, {2.0f, 0.2f, 0.5f}, {2.0f, 0.8f, 0.6f}};
  const Bounds3f box = ClipTriangleToCell(p, cell);
  ASSERT_FALSE(box.Empty());
  EXPECT_TRUE(box.Contains(Vec3f{1.0f, 0.5f, 0.5f}));
}

TEST(ClipTriangleToCell, HugeTriangleGivesTheCellsCrossSection) {
  const Bounds3f cell{{2, 3, 4}, {3, 5, 8}};
  const Vec3f p[3] = {{-1e4f, -1e4f, 6.25f}, {3e4f, -1e4f, 6.25f}, {-1e4f, 3e4f, 6.25f}};
  const Bounds3f box = ClipTriangleToCell(p, cell);
  EXPECT_EQ(box.lower, (Vec3f{2, 3, 6.25f}));
  EXPECT_EQ(box.upper, (Vec3f{3, 5, 6.25f}));
}

TEST(ClipTriangleToCell, FarFromTheOriginStaysConservative) {
  const Bounds3f cell{{1e6f, -2e6f, 3e6f}, {1e6f + 64, -2e6f + 64, 3e6f + 64}};
  EXPECT_GT(CheckRandomTriangles(cell, 2), 100);
  // And a huge triangle there still gives the whole cross-section.
  const Vec3f p[3] = {
      {0, -3e6f, 3e6f + 32}, {3e6f, -3e6f, 3e6f + 32}, {0, 0, 3e6f + 32}};
  const Bounds3f box = ClipTriangleToCell(p, cell);
  EXPECT_EQ(box.lower, (Vec3f{cell.lower.x, cell.lower.y, 3e6f + 32}));
  EXPECT_EQ(box.upper, (Vec3f{cell.upper.x, cell.upper.y, 3e6f + 32}));
}

}  // namespace
}  // namespace raystack::prep
