#include "common/image/image_layers.h"

#include <gtest/gtest.h>

#include <cmath>

namespace raystack::image {
namespace {

TEST(ImageLayers, ResizeAllocatesEveryLayer) {
  ImageLayers image;
  image.Resize(5, 3);
  EXPECT_EQ(image.width, 5);
  EXPECT_EQ(image.height, 3);
  EXPECT_EQ(image.pixel_count(), 15u);
  EXPECT_EQ(image.rgba.size(), 60u);
  EXPECT_EQ(image.z.size(), 15u);
  EXPECT_EQ(image.normal.size(), 45u);
  EXPECT_EQ(image.albedo.size(), 45u);
  EXPECT_EQ(image.samples.size(), 15u);
  EXPECT_EQ(image.variance.size(), 15u);
  for (float z : image.z) EXPECT_TRUE(std::isinf(z) && z > 0);
  for (float v : image.rgba) EXPECT_EQ(v, 0);
  EXPECT_EQ(image.PixelIndex(4, 2), 14u);
}

TEST(ImageLayers, ResizeResetsOldContents) {
  ImageLayers image;
  image.Resize(2, 2);
  image.rgba[0] = 7;
  image.z[0] = 1;
  image.samples[3] = 9;
  image.Resize(2, 2);
  EXPECT_EQ(image.rgba[0], 0);
  EXPECT_TRUE(std::isinf(image.z[0]));
  EXPECT_EQ(image.samples[3], 0u);
  image.Resize(0, 0);
  EXPECT_TRUE(image.rgba.empty());
}

}  // namespace
}  // namespace raystack::image
