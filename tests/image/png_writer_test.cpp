#include "common/image/png_writer.h"
#include "common/image/srgb8.h"

#include <gtest/gtest.h>
#include <png.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <string>
#include <vector>

#include "common/base/temp_dir.h"

namespace raystack::image {
namespace {

struct DecodedPng {
  uint32_t width = 0, height = 0;
  int bit_depth = 0, color_type = 0;
  std::vector<uint8_t> rgb;
};

// The whole file (a sized read: istreambuf_iterator trips GCC 12's -Wnull-dereference).
std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string bytes(static_cast<size_t>(std::filesystem::file_size(path)), '\0');
  in.read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  return bytes;
}

uint32_t BigEndian32(const std::string& bytes, size_t at) {
  return (uint32_t{static_cast<uint8_t>(bytes[at])} << 24) |
         (uint32_t{static_cast<uint8_t>(bytes[at + 1])} << 16) |
         (uint32_t{static_cast<uint8_t>(bytes[at + 2])} << 8) |
         uint32_t{static_cast<uint8_t>(bytes[at + 3])};
}

// The header straight from the bytes (signature, then IHDR first), the pixels through libpng.
bool Decode(const std::string& path, DecodedPng* out) {
  const std::string bytes = ReadBytes(path);
  static const unsigned char kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (bytes.size() < 33 || std::memcmp(bytes.data(), kSignature, 8) != 0 ||
      bytes.compare(12, 4, "IHDR") != 0)
    return false;
  out->width = BigEndian32(bytes, 16);
  out->height = BigEndian32(bytes, 20);
  out->bit_depth = static_cast<uint8_t>(bytes[24]);
  out->color_type = static_cast<uint8_t>(bytes[25]);

  png_image png;
  std::memset(&png, 0, sizeof png);
  png.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&png, path.c_str())) return false;
  png.format = PNG_FORMAT_RGB;
  out->rgb.resize(PNG_IMAGE_SIZE(png));
  if (!png_image_finish_read(&png, nullptr, out->rgb.data(), 0, nullptr)) return false;
  return png.width == out->width && png.height == out->height;
}

TEST(LinearToSrgb8, TransferCurve) {
  EXPECT_EQ(LinearToSrgb8(0), 0);
  EXPECT_EQ(LinearToSrgb8(-1), 0);
  EXPECT_EQ(LinearToSrgb8(std::numeric_limits<float>::quiet_NaN()), 0);
  EXPECT_EQ(LinearToSrgb8(1), 255);
  EXPECT_EQ(LinearToSrgb8(1e30f), 255);
  EXPECT_EQ(LinearToSrgb8(std::numeric_limits<float>::infinity()), 255);
  EXPECT_EQ(LinearToSrgb8(0.5f), 188);       // 1.055 * 0.5^(1/2.4) - 0.055 = 0.7354
  EXPECT_EQ(LinearToSrgb8(0.0031308f), 10);  // the knee: 12.92 * 0.0031308 = 0.04045
  EXPECT_EQ(LinearToSrgb8(0.18f), 118);      // middle grey
  int previous = 0;
  for (int i = 0; i <= 1000; ++i) {
    const int code = LinearToSrgb8(static_cast<float>(i) / 1000.0f);
    EXPECT_GE(code, previous);
    previous = code;
  }
}

TEST(WritePng, HeaderSizeAndPixels) {
  TempDir dir = TempDir::Create().value();
  ImageLayers image;
  image.Resize(3, 2);
  const float values[6][3] = {{0, 0.5f, 1},
                              {2, -1, std::numeric_limits<float>::quiet_NaN()},
                              {0.18f, 0.18f, 0.18f},
                              {1, 0, 0},
                              {0, 1, 0},
                              {0.25f, 0.25f, 0.25f}};
  for (size_t i = 0; i < 6; ++i)
    for (size_t c = 0; c < 3; ++c) image.rgba[4 * i + c] = values[i][c];
  const std::string path = dir.File("look.png");
  ASSERT_TRUE(WritePng(path, image).ok());

  DecodedPng png;
  ASSERT_TRUE(Decode(path, &png));
  EXPECT_EQ(png.width, 3u);
  EXPECT_EQ(png.height, 2u);
  EXPECT_EQ(png.bit_depth, 8);
  EXPECT_EQ(png.color_type, PNG_COLOR_TYPE_RGB);
  const std::vector<uint8_t> expected = {0,   188, 255, 255, 0,   0, 118, 118, 118,
                                         255, 0,   0,   0,   255, 0, 137, 137, 137};
  EXPECT_EQ(png.rgb, expected);  // row 0 (the top) first
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir.path()),
                          std::filesystem::directory_iterator()),
            1);
}

TEST(WritePng, ExposureScalesByPowersOfTwo) {
  TempDir dir = TempDir::Create().value();
  ImageLayers image;
  image.Resize(1, 1);
  image.rgba[0] = image.rgba[1] = image.rgba[2] = 0.25f;
  ASSERT_TRUE(WritePng(dir.File("a.png"), image, 1.0f).ok());  // 0.25 * 2 = 0.5
  DecodedPng png;
  ASSERT_TRUE(Decode(dir.File("a.png"), &png));
  EXPECT_EQ(png.rgb, (std::vector<uint8_t>{188, 188, 188}));
  ASSERT_TRUE(WritePng(dir.File("a.png"), image, -2.0f).ok());  // 0.0625
  ASSERT_TRUE(Decode(dir.File("a.png"), &png));
  EXPECT_EQ(png.rgb[0], LinearToSrgb8(0.0625f));
}

TEST(WritePng, ErrorsNameThePath) {
  TempDir dir = TempDir::Create().value();
  ImageLayers image;
  image.Resize(2, 2);
  const std::string missing = dir.File("nowhere/look.png");
  Status status = WritePng(missing, image);
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.message().find(missing), std::string::npos) << status.message();
  image.rgba.resize(3);
  status = WritePng(dir.File("look.png"), image);
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.message().find(dir.File("look.png")), std::string::npos);
  status = WritePng(dir.File("look.png"), ImageLayers{});
  EXPECT_FALSE(status.ok());
}

}  // namespace
}  // namespace raystack::image
