#include "tools/import/polygon_split.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

namespace raystack::import {
namespace {

using Triangle = PolygonSplitter::Triangle;

struct Point2 {
  double x, y;
};

double Area2(Point2 a, Point2 b, Point2 c) { return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x); }

double PolygonArea2(const std::vector<Point2>& p) {
  double sum = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    const Point2 a = p[i], b = p[(i + 1) % p.size()];
    sum += a.x * b.y - b.x * a.y;
  }
  return sum;
}

bool Inside(const std::vector<Point2>& p, Point2 q) {  // even-odd rule
  bool in = false;
  for (size_t i = 0, j = p.size() - 1; i < p.size(); j = i++)
    if ((p[i].y > q.y) != (p[j].y > q.y) &&
        q.x < (p[j].x - p[i].x) * (q.y - p[i].y) / (p[j].y - p[i].y) + p[i].x)
      in = !in;
  return in;
}

// The face in the plane z = 0 (the splitter's own frame when its normal is +z).
std::vector<Vec3f> InPlaneZ(const std::vector<Point2>& p) {
  std::vector<Vec3f> out;
  for (const Point2& q : p) out.push_back({static_cast<float>(q.x), static_cast<float>(q.y), 0});
  return out;
}

// A split covers the face exactly: n - 2 triangles, each turning the face's way, inside it,
// their areas adding up to the face's.
void ExpectCovers(const std::vector<Point2>& face, const std::vector<Triangle>& triangles) {
  ASSERT_EQ(triangles.size(), face.size() - 2);
  const double area = PolygonArea2(face);
  double sum = 0;
  for (const Triangle& t : triangles) {
    const double a = Area2(face[t[0]], face[t[1]], face[t[2]]);
    EXPECT_GE(a * area, 0) << "a triangle against the face's winding";
    sum += std::fabs(a);
    const Point2 centroid{(face[t[0]].x + face[t[1]].x + face[t[2]].x) / 3,
                          (face[t[0]].y + face[t[1]].y + face[t[2]].y) / 3};
    if (std::fabs(a) > 1e-9 * std::fabs(area)) {
      EXPECT_TRUE(Inside(face, centroid)) << "a triangle outside the face";
    }
  }
  EXPECT_NEAR(sum, std::fabs(area), 1e-9 * std::fabs(area));
}

TEST(PolygonSplitter, ConvexFacesAreFansFromTheirFirstCorner) {
  PolygonSplitter splitter;
  std::vector<Triangle> triangles;
  std::vector<Point2> hexagon;
  for (int i = 0; i < 6; ++i)
    hexagon.push_back({std::cos(i * std::numbers::pi / 3), std::sin(i * std::numbers::pi / 3)});
  ASSERT_TRUE(splitter.Split(InPlaneZ(hexagon), &triangles));
  ASSERT_EQ(triangles.size(), 4u);
  for (uint32_t i = 0; i < 4; ++i) EXPECT_EQ(triangles[i], (Triangle{0, i + 1, i + 2}));
  // A non-planar quad, as scanners write them: still the fan it always was.
  const std::vector<Vec3f> quad = {{0, 0, 0}, {1, 0, 0.2f}, {1, 1, 0}, {0, 1, 0.3f}};
  ASSERT_TRUE(splitter.Split(quad, &triangles));
  EXPECT_EQ(triangles, (std::vector<Triangle>{{0, 1, 2}, {0, 2, 3}}));
}

TEST(PolygonSplitter, AnLShapedFaceListedFromItsNotchIsNotFilledIn) {
  // The face a helper wrote as Blender does: listed from the corner of the notch, whose fan
  // covered the notch (x > 1, y > 1) with a triangle outside the face.
  const std::vector<Point2> l_shape = {{2, 1}, {1, 1}, {1, 2}, {0, 2}, {0, 0}, {2, 0}};
  PolygonSplitter splitter;
  std::vector<Triangle> triangles;
  ASSERT_TRUE(splitter.Split(InPlaneZ(l_shape), &triangles));
  ExpectCovers(l_shape, triangles);
  for (const Triangle& t : triangles) {
    const double cx = (l_shape[t[0]].x + l_shape[t[1]].x + l_shape[t[2]].x) / 3;
    const double cy = (l_shape[t[0]].y + l_shape[t[1]].y + l_shape[t[2]].y) / 3;
    EXPECT_FALSE(cx > 1 && cy > 1) << "a triangle in the notch";
  }
}

// A corner written twice in a row turns by 0 at both copies: the notch of the L hid behind it,
// the face was taken for convex and fanned over its notch (found by the day's review).
TEST(PolygonSplitter, ARepeatedCornerDoesNotHideANotch) {
  const std::vector<Point2> l_shape = {{2, 1}, {1, 1}, {1, 1}, {1, 2}, {0, 2}, {0, 0}, {2, 0}, {2, 1}};
  PolygonSplitter splitter;
  std::vector<Triangle> triangles;
  ASSERT_TRUE(splitter.Split(InPlaneZ(l_shape), &triangles));
  ASSERT_EQ(triangles.size(), 4u);  // the six distinct corners' four
  double sum = 0;
  for (const Triangle& t : triangles) {
    const double a = Area2(l_shape[t[0]], l_shape[t[1]], l_shape[t[2]]);
    EXPECT_GT(a * PolygonArea2(l_shape), 0) << "a triangle against the face's winding";
    sum += std::fabs(a);
  }
  EXPECT_NEAR(sum, 6.0, 1e-12);  // twice the L's area, 3
}

// A sawtooth ribbon of 4,096 corners: every clip made one new ear behind the walk, which then
// went round the whole ring, each look O(n): cubic, 1.3 s a face (found by the day's review;
// 0.06 s with the list of ears). Here its split is checked; its time is not asserted.
TEST(PolygonSplitter, ASawtoothRibbonIsCoveredExactly) {
  std::vector<Point2> ribbon;
  const int half = static_cast<int>(PolygonSplitter::kMaxClippedCorners) / 2;
  for (int i = 0; i < half; ++i) ribbon.push_back({double(i), (i % 2) * 1.0});
  for (int i = half - 1; i >= 0; --i) ribbon.push_back({double(i), (i % 2) * 1.0 + 0.5});
  PolygonSplitter splitter;
  std::vector<Triangle> triangles;
  ASSERT_TRUE(splitter.Split(InPlaneZ(ribbon), &triangles));
  ExpectCovers(ribbon, triangles);
}

TEST(PolygonSplitter, RandomConcaveFacesInAnyPlaneAndWindingAreCovered) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> radius(0.2, 1.0), unit(-1.0, 1.0);
  PolygonSplitter splitter;
  std::vector<Triangle> triangles;
  for (int trial = 0; trial < 300; ++trial) {
    // Star-shaped about the origin: simple, and concave wherever the radius dips.
    const int n = 4 + trial % 40;
    std::vector<Point2> face;
    for (int i = 0; i < n; ++i) {
      const double angle = 2 * std::numbers::pi * i / n, r = radius(rng);
      face.push_back({r * std::cos(angle), r * std::sin(angle)});
    }
    if (trial % 2) std::reverse(face.begin(), face.end());  // clockwise
    // Placed in 3D on a random plane, far from the origin (georeferenced models are).
    Vec3f e1{static_cast<float>(unit(rng)), static_cast<float>(unit(rng)),
             static_cast<float>(unit(rng))};
    e1 = Normalize(e1);
    Vec3f e2 = Normalize(Cross(e1, Normalize(Vec3f{0.3f, -0.5f, 0.8f})));
    const Vec3f offset{1000, -2000, 500};
    std::vector<Vec3f> corners;
    std::vector<Point2> planar;  // the corners as float gave them, in the plane's frame
    for (const Point2& p : face) {
      corners.push_back(offset + e1 * static_cast<float>(p.x) + e2 * static_cast<float>(p.y));
      const Vec3f d = corners.back() - offset;
      planar.push_back({Dot(d, e1), Dot(d, e2)});
    }
    ASSERT_TRUE(splitter.Split(corners, &triangles));
    ASSERT_EQ(triangles.size(), face.size() - 2) << "trial " << trial;
    // Each triangle faces the face's way in 3D (its normal along the plane's, signed as the
    // face winds), and in the plane the triangles cover the face.
    const Vec3f plane_normal = Cross(e1, e2) * static_cast<float>(PolygonArea2(face) > 0 ? 1 : -1);
    for (const Triangle& t : triangles) {
      const Vec3f facing = Cross(corners[t[1]] - corners[t[0]], corners[t[2]] - corners[t[0]]);
      EXPECT_GE(Dot(facing, plane_normal), -1e-3f) << "trial " << trial;
    }
    double sum = 0;
    for (const Triangle& t : triangles) sum += std::fabs(Area2(face[t[0]], face[t[1]], face[t[2]]));
    EXPECT_NEAR(sum, std::fabs(PolygonArea2(face)), 1e-4) << "trial " << trial;
  }
}

TEST(PolygonSplitter, FacesThatCrossThemselvesOrHaveNoAreaStillGiveTheirTriangles) {
  PolygonSplitter splitter;
  std::vector<Triangle> triangles;
  const std::vector<Vec3f> bowtie = {{0, 0, 0}, {1, 1, 0}, {1, 0, 0}, {0, 1, 0}, {0.5f, 2, 0}};
  EXPECT_TRUE(splitter.Split(bowtie, &triangles));
  EXPECT_EQ(triangles.size(), 3u);
  const std::vector<Vec3f> line = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {3, 0, 0}, {4, 0, 0}};
  EXPECT_TRUE(splitter.Split(line, &triangles));
  EXPECT_EQ(triangles.size(), 3u);
  const std::vector<Vec3f> nan = {{0, 0, 0}, {NAN, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  EXPECT_TRUE(splitter.Split(nan, &triangles));
  EXPECT_EQ(triangles.size(), 2u);
}

// A comb: its top a zigzag whose every other corner turns the other way.
std::vector<Point2> Comb(size_t corners) {
  std::vector<Point2> comb;
  const auto top = static_cast<int>(corners - 2);
  for (int i = 0; i < top; ++i) comb.push_back({double(i), i % 2 ? 1.0 : 2.0});
  comb.push_back({double(top - 1), 0});
  comb.push_back({0, 0});
  return comb;
}

TEST(PolygonSplitter, ANonConvexFaceTooLargeToClipIsAFanAndSaysSo) {
  PolygonSplitter splitter;
  std::vector<Triangle> triangles;
  const std::vector<Point2> large = Comb(PolygonSplitter::kMaxClippedCorners + 1);
  EXPECT_FALSE(splitter.Split(InPlaneZ(large), &triangles));
  ASSERT_EQ(triangles.size(), large.size() - 2);
  EXPECT_EQ(triangles[5], (Triangle{0, 6, 7}));
  const std::vector<Point2> largest_clipped = Comb(PolygonSplitter::kMaxClippedCorners);
  EXPECT_TRUE(splitter.Split(InPlaneZ(largest_clipped), &triangles));
  ExpectCovers(largest_clipped, triangles);
}

}  // namespace
}  // namespace raystack::import
