// The page's quadtree fill, in a real headless Chromium: a film where only some pixels are
// computed is served, and the canvas the page draws is read back and compared with the rule
// (thesis Fig. VI.11): a pixel without samples shows its nearest computed ancestor, the pixel
// with the low k bits of x and y cleared for k = 1..4; with none, it stays transparent.

#include <gtest/gtest.h>

#include <set>
#include <utility>

#include "common/base/temp_dir.h"
#include "common/image/srgb8.h"
#include "master/preview/preview_server.h"
#include "tests/preview/headless_chromium.h"

namespace raystack::master::preview {
namespace {

using testing::DecodeBase64;
using testing::HeadlessChromium;

constexpr int kWidth = 48, kHeight = 40;  // not a multiple of 16 in y: cropped squares too

float Value(int x, int y, int c) { return static_cast<float>((x * 5 + y * 3 + c * 70) % 256) / 300.0f; }

TEST(BrowserPreview, UncomputedPixelsTakeTheirNearestComputedAncestor) {
  if (!HeadlessChromium::Installed())
    GTEST_SKIP() << HeadlessChromium::kBinary << " is missing (Debian package chromium; CI installs it)";
  std::set<std::pair<int, int>> computed;
  for (int y = 0; y < kHeight; ++y)
    for (int x = 0; x < kWidth; ++x) {
      const bool level4 = x % 16 == 0 && y % 16 == 0 && !(x == 16 && y == 16);  // one square has none
      const bool level2 = x < 16 && y < 16 && x % 4 == 0 && y % 4 == 0;
      const bool level1 = x >= 32 && y < 16 && x % 2 == 0 && y % 2 == 0;
      const bool scattered = (x * 7 + y * 13) % 23 == 0;
      if (level4 || level2 || level1 || scattered) computed.insert({x, y});
    }
  render::Film film(kWidth, kHeight);
  std::vector<render::SampleResult> batch;
  for (auto [x, y] : computed) {
    render::SampleResult s{};
    s.pixel = static_cast<uint32_t>(y * kWidth + x);
    for (int c = 0; c < 3; ++c) s.rgb[c] = Value(x, y, c);
    batch.push_back(s);
  }
  film.Merge(batch);

  Expected<std::unique_ptr<PreviewServer>> server = PreviewServer::Start(ServerOptions{});
  ASSERT_TRUE(server.ok()) << server.status().message();
  (*server)->AttachFilm(&film, 0);
  (*server)->DetachFilm();  // the final copy, which a new viewer gets at once

  Expected<TempDir> profile = TempDir::Create();
  ASSERT_TRUE(profile.ok());
  HeadlessChromium browser;
  std::string error;
  ASSERT_TRUE(browser.Start(profile->path(), &error)) << error;
  ASSERT_TRUE(browser.Open((*server)->Url(), &error)) << error;
  ASSERT_TRUE(browser.WaitFor("window.preview !== undefined && preview.frames > 0",
                              std::chrono::seconds(60), &error)) << error;
  const std::vector<uint8_t> canvas = DecodeBase64(browser.Evaluate("preview.pixels()", &error).get<std::string>());
  ASSERT_TRUE(error.empty()) << error;
  ASSERT_EQ(canvas.size(), 4u * kWidth * kHeight);

  int filled = 0, empty = 0;
  for (int y = 0; y < kHeight; ++y)
    for (int x = 0; x < kWidth; ++x) {
      int sx = -1, sy = -1;  // the pixel whose colour (x, y) should show
      for (int k = 0; k <= 4 && sx < 0; ++k) {
        const int ax = x & ~((1 << k) - 1), ay = y & ~((1 << k) - 1);
        if (computed.count({ax, ay})) sx = ax, sy = ay;
      }
      const uint8_t* p = &canvas[4 * static_cast<size_t>(y * kWidth + x)];
      if (sx < 0) {
        ++empty;
        EXPECT_EQ(p[3], 0) << "(" << x << "," << y << ") has no computed ancestor";
        continue;
      }
      if (sx != x || sy != y) ++filled;
      for (int c = 0; c < 3; ++c)
        ASSERT_EQ(p[c], image::LinearToSrgb8(Value(sx, sy, c)))
            << "pixel (" << x << "," << y << ") channel " << c << " should show (" << sx << "," << sy << ")";
      ASSERT_EQ(p[3], 255) << x << "," << y;
    }
  EXPECT_GT(filled, kWidth * kHeight / 2);  // most of the image is filled from ancestors
  EXPECT_GT(empty, 0);                      // and the square without one stays empty
}

}  // namespace
}  // namespace raystack::master::preview
