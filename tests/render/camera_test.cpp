#include "common/render/camera.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>

namespace raystack::render {
namespace {

constexpr float kEps = 1e-5f;

float DegToRad(float deg) { return deg * std::numbers::pi_v<float> / 180.0f; }

void ExpectNear(Vec3f a, Vec3f b, float eps = kEps) {
  EXPECT_NEAR(a.x, b.x, eps);
  EXPECT_NEAR(a.y, b.y, eps);
  EXPECT_NEAR(a.z, b.z, eps);
}

CameraDesc Desc(Vec3f position, Vec3f look_at, Vec3f up, float fov, int width, int height) {
  CameraDesc desc;
  desc.position = position;
  desc.look_at = look_at;
  desc.up = up;
  desc.fov_y_deg = fov;
  desc.width = width;
  desc.height = height;
  return desc;
}

TEST(Camera, CentreRayPointsAtLookAt) {
  const CameraDesc desc = Desc({1, 2, 3}, {-2, 0.5f, -4}, {0, 1, 0}, 55, 640, 480);
  const Camera camera(desc);
  EXPECT_EQ(camera.width(), 640);
  EXPECT_EQ(camera.height(), 480);
  const Ray ray = camera.Generate(320, 240);
  EXPECT_EQ(ray.origin, desc.position);
  EXPECT_EQ(ray.tmin, 0);
  EXPECT_EQ(ray.tmax, std::numeric_limits<float>::infinity());
  ExpectNear(ray.direction, Normalize(desc.look_at - desc.position));
}

TEST(Camera, CornerRaysHaveTheFieldOfView) {
  const float fov = 60;
  const int width = 800, height = 400;
  const Camera camera(Desc({0, 0, 5}, {0, 0, 0}, {0, 1, 0}, fov, width, height));
  const float tan_half = std::tan(DegToRad(fov / 2));
  const float aspect = static_cast<float>(width) / static_cast<float>(height);
  // Looking down -z with y up: right is +x.
  const Vec3f top_left = camera.Generate(0, 0).direction;
  EXPECT_NEAR(Length(top_left), 1, kEps);
  EXPECT_NEAR(top_left.y / -top_left.z, tan_half, kEps);
  EXPECT_NEAR(top_left.x / -top_left.z, -tan_half * aspect, kEps);
  const Vec3f bottom_right =
      camera.Generate(static_cast<float>(width), static_cast<float>(height)).direction;
  EXPECT_NEAR(bottom_right.y / -bottom_right.z, -tan_half, kEps);
  EXPECT_NEAR(bottom_right.x / -bottom_right.z, tan_half * aspect, kEps);
  // The vertical angle between the top and bottom edge midpoints is the fov.
  const Vec3f top = camera.Generate(width / 2.0f, 0).direction;
  const Vec3f bottom = camera.Generate(width / 2.0f, static_cast<float>(height)).direction;
  EXPECT_NEAR(std::acos(Dot(top, bottom)), DegToRad(fov), 1e-4f);
}

TEST(Camera, YGrowsDownwardAndXToTheRight) {
  const Vec3f up{0.3f, 1, 0.2f};  // need not be perpendicular to the view direction
  const Camera camera(Desc({2, 1, 2}, {0, 0, 0}, up, 40, 100, 100));
  const Vec3f centre = camera.Generate(50, 50).direction;
  const Vec3f high = camera.Generate(50, 1).direction;
  const Vec3f low = camera.Generate(50, 99).direction;
  EXPECT_GT(Dot(high, up), Dot(centre, up));
  EXPECT_LT(Dot(low, up), Dot(centre, up));
  const Vec3f right = Cross(centre, up);
  EXPECT_GT(Dot(camera.Generate(99, 50).direction, right), 0);
  EXPECT_LT(Dot(camera.Generate(1, 50).direction, right), 0);
}

TEST(Camera, FrameIsOrthonormalAndRightHanded) {
  const Camera camera(Desc({3, 4, -1}, {0, 1, 2}, {0, 0, 1}, 30, 64, 48));
  const Vec3f f = camera.forward(), r = camera.right(), u = camera.up();
  EXPECT_NEAR(Length(f), 1, kEps);
  EXPECT_NEAR(Length(r), 1, kEps);
  EXPECT_NEAR(Length(u), 1, kEps);
  EXPECT_NEAR(Dot(f, r), 0, kEps);
  EXPECT_NEAR(Dot(f, u), 0, kEps);
  EXPECT_NEAR(Dot(r, u), 0, kEps);
  ExpectNear(Cross(f, u), r);
  EXPECT_GT(u.z, 0);  // on the side of the given up
}

TEST(Camera, PixelCentresAreSymmetric) {
  const int width = 7, height = 5;
  const Camera camera(Desc({0, 0, 0}, {0, 0, -1}, {0, 1, 0}, 90, width, height));
  for (int j = 0; j < height; ++j) {
    for (int i = 0; i < width; ++i) {
      const Vec3f d = camera.Generate(i + 0.5f, j + 0.5f).direction;
      const Vec3f mirrored = camera.Generate(width - i - 0.5f, height - j - 0.5f).direction;
      EXPECT_NEAR(d.x, -mirrored.x, kEps);
      EXPECT_NEAR(d.y, -mirrored.y, kEps);
      EXPECT_NEAR(d.z, mirrored.z, kEps);
    }
  }
  // Square pixels: one pixel step spans the same plane distance both ways (90 deg: plane at
  // z = -1 is 2 units tall, so a step is 2 / height).
  const Vec3f a = camera.Generate(3.5f, 2.5f).direction, b = camera.Generate(4.5f, 2.5f).direction,
              c = camera.Generate(3.5f, 3.5f).direction;
  EXPECT_NEAR(b.x / -b.z - a.x / -a.z, 2.0f / height, kEps);
  EXPECT_NEAR(a.y / -a.z - c.y / -c.z, 2.0f / height, kEps);
}

TEST(Camera, FarAwayCameraStillHasAFrame) {
  const Camera camera(Desc({1e30f, 0, 0}, {-1e30f, 0, 0}, {0, 1, 0}, 40, 10, 10));
  ExpectNear(camera.Generate(5, 5).direction, {-1, 0, 0});
}

TEST(CameraDeathTest, InvalidDescriptionIsABug) {
  EXPECT_DEATH(Camera(Desc({1, 1, 1}, {1, 1, 1}, {0, 1, 0}, 40, 10, 10)), "CHECK");
  EXPECT_DEATH(Camera(Desc({0, 0, 1}, {0, 0, 0}, {0, 0, 1}, 40, 10, 10)), "CHECK");
  EXPECT_DEATH(Camera(Desc({0, 0, 1}, {0, 0, 0}, {0, 1, 0}, 40, 0, 10)), "CHECK");
}

}  // namespace
}  // namespace raystack::render
