// Progressive passes: the sweeps of a plan cover every (pixel, sample) of the frame exactly
// once, pass by pass, whatever the order and pass size.

#include "common/render/frame_plan.h"

#include <gtest/gtest.h>

#include <vector>

#include "common/render/pixel_priority.h"

namespace raystack::render {
namespace {

TEST(PassRanges, DoublingAndFixed) {
  const std::vector<SampleRange> d = PassRanges(16, 0);
  std::vector<uint32_t> ends;
  for (const SampleRange& r : d) ends.push_back(r.end);
  EXPECT_EQ(ends, (std::vector<uint32_t>{1, 2, 4, 8, 16}));
  EXPECT_EQ(PassRanges(10, 0).back().end, 10u);  // the last pass is cut to spp
  EXPECT_EQ(PassRanges(10, 0).back().begin, 8u);
  const std::vector<SampleRange> f = PassRanges(10, 4);
  ASSERT_EQ(f.size(), 3u);
  EXPECT_EQ(f[1].begin, 4u);
  EXPECT_EQ(f[2].end, 10u);
  EXPECT_TRUE(PassRanges(0, 0).empty());
}

TEST(FramePlan, SweepsCoverEveryPixelSampleOnceInPassOrder) {
  for (PixelOrder order : {PixelOrder::kPriority, PixelOrder::kScanline})
    for (uint32_t pass_spp : {0u, 3u}) {
      const int w = 45, h = 37;
      const uint32_t spp = 7;
      const FramePlan plan = MakeFramePlan(w, h, 16, spp, pass_spp, order);
      EXPECT_EQ(plan.spp(), spp);
      std::vector<int> seen(static_cast<size_t>(w) * h * spp, 0);
      uint32_t pass = 0;
      for (const Sweep& sweep : plan.sweeps) {
        EXPECT_GE(sweep.pass, pass);  // passes never go back
        pass = sweep.pass;
        for (const Tile& t : sweep.tiles) {
          EXPECT_GE(t.sample_begin, plan.passes[sweep.pass].begin);
          EXPECT_LE(t.sample_end, plan.passes[sweep.pass].end);
          EXPECT_LE(TileSamples(t, spp), kMaxTileSamples);
          uint64_t counted = 0;
          for (int y = t.y0; y < t.y1; ++y)
            for (int x = t.x0; x < t.x1; ++x) {
              const uint16_t rank = PixelRank(x, y);
              if (rank < t.rank_begin || rank >= t.rank_end) continue;
              for (uint32_t s = t.sample_begin; s < t.sample_end; ++s) {
                ++seen[(static_cast<size_t>(y) * w + x) * spp + s];
                ++counted;
              }
            }
          EXPECT_EQ(counted, TileSamples(t, spp));
        }
      }
      for (int n : seen) ASSERT_EQ(n, 1);
      EXPECT_EQ(plan.total_samples(), static_cast<uint64_t>(w) * h * spp);
    }
}

TEST(FramePlan, ALargePassIsCutIntoSweepsOfBoundedTiles) {
  const FramePlan plan = MakeFramePlan(40, 40, 32, 4096, 0, PixelOrder::kScanline);
  ASSERT_EQ(plan.passes.back().begin, 2048u);
  uint64_t total = 0;
  for (const Sweep& sweep : plan.sweeps)
    for (const Tile& t : sweep.tiles) {
      EXPECT_LE(TileSamples(t, 4096), kMaxTileSamples);
      total += TileSamples(t, 4096);
    }
  EXPECT_EQ(total, plan.total_samples());
  EXPECT_TRUE(plan.sweeps.back().pass_end);
  EXPECT_FALSE(plan.sweeps[plan.sweeps.size() - 2].pass_end);
}

TEST(FramePlan, PriorityFirstPassStartsSparseAndEven) {
  const FramePlan plan = MakeFramePlan(64, 64, 32, 4, 0, PixelOrder::kPriority);
  ASSERT_EQ(plan.sweeps.size(), 5u + 2u);  // 5 rounds of pass 1, then passes 2 and 3
  // The first round: one pixel per 16x16 square, all over the frame.
  uint64_t first = 0;
  for (const Tile& t : plan.sweeps[0].tiles) first += TileSamples(t, 4);
  EXPECT_EQ(first, 64u * 64u / 256u);
  EXPECT_FALSE(plan.sweeps[0].pass_end);
  EXPECT_TRUE(plan.sweeps[4].pass_end);
  const FramePlan scan = MakeFramePlan(64, 64, 32, 4, 0, PixelOrder::kScanline);
  EXPECT_EQ(scan.sweeps.size(), 3u);
  EXPECT_EQ(scan.sweeps[0].tiles[1].x0, 32);  // left to right first
  EXPECT_EQ(scan.sweeps[0].tiles[1].y0, 0);
}

TEST(PixelOrder, ParsesItsNamesAndRefusesOthers) {
  Expected<PixelOrder> p = ParsePixelOrder("priority"), s = ParsePixelOrder("scanline");
  ASSERT_TRUE(p.ok() && s.ok());
  EXPECT_EQ(*p, PixelOrder::kPriority);
  EXPECT_EQ(*s, PixelOrder::kScanline);
  EXPECT_FALSE(ParsePixelOrder("hilbert").ok());
}

}  // namespace
}  // namespace raystack::render
