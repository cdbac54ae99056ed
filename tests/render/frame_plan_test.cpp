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
      uint64_t samples = 0;
      for (size_t i = 0; i < plan.sweeps.size(); ++i) {
        const Sweep& sweep = plan.sweeps[i];
        EXPECT_GE(sweep.pass, pass);  // passes never go back
        pass = sweep.pass;
        const std::vector<Tile> tiles = plan.Tiles(i);
        EXPECT_EQ(tiles.size(), sweep.tile_count);
        for (const Tile& t : tiles) {
          samples += TileSamples(t, spp);
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
      EXPECT_EQ(plan.samples_to_render(), samples);
    }
}

TEST(FramePlan, ALargePassIsCutIntoSweepsOfBoundedTiles) {
  const FramePlan plan = MakeFramePlan(40, 40, 32, 4096, 0, PixelOrder::kScanline);
  ASSERT_EQ(plan.passes.back().begin, 2048u);
  uint64_t total = 0;
  for (size_t i = 0; i < plan.sweeps.size(); ++i)
    for (const Tile& t : plan.Tiles(i)) {
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
  for (const Tile& t : plan.Tiles(0)) first += TileSamples(t, 4);
  EXPECT_EQ(first, 64u * 64u / 256u);
  EXPECT_FALSE(plan.sweeps[0].pass_end);
  EXPECT_TRUE(plan.sweeps[4].pass_end);
  const FramePlan scan = MakeFramePlan(64, 64, 32, 4, 0, PixelOrder::kScanline);
  EXPECT_EQ(scan.sweeps.size(), 3u);
  EXPECT_EQ(scan.Tiles(0)[1].x0, 32);  // left to right first
  EXPECT_EQ(scan.Tiles(0)[1].y0, 0);
}

// Found by the scale review: the plan held every sweep's tiles, made at once: 64 M tiles (1.9
// GB, and 30 GB at 65,535 samples) for 16k x 16k pixels at 4,096 samples. The sweeps share
// their grid; a sweep's tiles are made as it is handed out.
TEST(FramePlan, ItsSweepsShareOneGridOfRectangles) {
  const FramePlan plan = MakeFramePlan(16384, 16384, 16, 4096, 0, PixelOrder::kScanline);
  ASSERT_GT(plan.sweeps.size(), 60u);
  for (const Sweep& sweep : plan.sweeps) {
    EXPECT_EQ(sweep.grid.get(), plan.sweeps[0].grid.get());
    EXPECT_EQ(sweep.tile_count, 1024u * 1024u);
  }
  EXPECT_EQ(plan.samples_to_render(), plan.total_samples());
  // A round's larger tiles are a grid of their own, shared the same way.
  const FramePlan rounds = MakeFramePlan(64, 64, 8, 4, 0, PixelOrder::kPriority);
  EXPECT_NE(rounds.sweeps[0].grid.get(), rounds.sweeps[5].grid.get());
  EXPECT_EQ(rounds.sweeps[4].grid.get(), rounds.sweeps[5].grid.get());  // the last round: full tiles
}

// --resume's filter: the sweeps keep exactly the tiles it accepts, asked once per tile of each
// grid and rank range (the review of the lazy plan: asked again for every sweep, under the
// tile source's lock, and the checkpoint image kept alive for the frame by the filter).
TEST(FramePlan, KeepAsksOncePerGridTileAndLeavesOutWhatItRefuses) {
  for (PixelOrder order : {PixelOrder::kPriority, PixelOrder::kScanline}) {
    FramePlan plan = MakeFramePlan(70, 50, 8, 600, 0, order);
    const FramePlan whole = plan;
    auto refused = [](const Tile& t) { return (t.x0 / 8 + t.y0 / 8) % 3 == 0; };
    uint64_t asked = 0;
    plan.Keep([&](const Tile& t) {
      ++asked;
      return !refused(t);
    });
    uint64_t grid_tiles = 0;  // one per tile of each distinct (grid, ranks)
    for (size_t i = 0; i < whole.sweeps.size(); ++i) {
      bool seen = false;
      for (size_t j = 0; j < i; ++j)
        seen = seen || (whole.sweeps[j].grid == whole.sweeps[i].grid &&
                        whole.sweeps[j].rank_begin == whole.sweeps[i].rank_begin &&
                        whole.sweeps[j].rank_end == whole.sweeps[i].rank_end);
      if (!seen) grid_tiles += whole.sweeps[i].grid->size();
      std::vector<Tile> expected = whole.Tiles(i);
      std::erase_if(expected, refused);
      const std::vector<Tile> got = plan.Tiles(i);
      ASSERT_EQ(got.size(), expected.size()) << i;
      EXPECT_EQ(plan.sweeps[i].tile_count, expected.size()) << i;
      for (size_t k = 0; k < got.size(); ++k) {
        EXPECT_EQ(got[k].x0, expected[k].x0);
        EXPECT_EQ(got[k].y0, expected[k].y0);
        EXPECT_EQ(got[k].sample_begin, expected[k].sample_begin);
        EXPECT_EQ(got[k].rank_begin, expected[k].rank_begin);
      }
    }
    EXPECT_EQ(asked, grid_tiles);
    EXPECT_LT(asked, whole.sweeps.size() * whole.sweeps.back().grid->size() / 2);
    EXPECT_LT(plan.samples_to_render(), whole.samples_to_render());
  }
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
