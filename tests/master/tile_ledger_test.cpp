// The master's ledger of tiles in flight: samples must belong to a tile their slave was given
// and come once; a lost slave's unfinished tiles come back with the samples to take back out.

#include "master/tile_ledger.h"

#include <gtest/gtest.h>

#include <vector>

namespace raystack::master {
namespace {

constexpr int kWidth = 16;

render::SampleResult At(int x, int y, uint32_t sample) {
  render::SampleResult s{};
  s.pixel = static_cast<uint32_t>(y * kWidth + x);
  s.sample = sample;
  return s;
}

// Every sample of the 4 x 4 tile at (4, 8), samples [1, 3) of each pixel.
std::vector<render::SampleResult> AllOf(const render::Tile& t) {
  std::vector<render::SampleResult> all;
  for (int y = t.y0; y < t.y1; ++y)
    for (int x = t.x0; x < t.x1; ++x)
      for (uint32_t s = t.sample_begin; s < t.sample_end; ++s) all.push_back(At(x, y, s));
  return all;
}

TEST(TileLedger, ATileFinishesWithEachOfItsSamplesOnce) {
  const render::Tile tile{4, 8, 8, 12, 1, 3};
  TileLedger ledger(kWidth, 4);
  ledger.Assign(tile, 1);
  const std::vector<render::SampleResult> all = AllOf(tile);
  ASSERT_TRUE(ledger.Record(1, std::span(all).first(all.size() - 1)).ok());
  EXPECT_EQ(ledger.unfinished(), 1u);
  ASSERT_TRUE(ledger.Record(1, std::span(all).last(1)).ok());
  EXPECT_EQ(ledger.unfinished(), 0u);
}

// A finished tile's vector of kept samples serves the next tile (its memory already mapped):
// cleared, so a lost slave's next tile gives back only its own samples; and the search that
// starts at the last sample's tile still finds samples of the others.
TEST(TileLedger, AFinishedTilesMemoryServesTheNextOneEmpty) {
  const render::Tile first{4, 8, 8, 12, 1, 3}, second{0, 0, 4, 4, 0, 2}, other{8, 0, 12, 4, 0, 2};
  TileLedger ledger(kWidth, 4);
  ledger.Assign(first, 1);
  const std::vector<render::SampleResult> all = AllOf(first);
  ASSERT_TRUE(ledger.Record(1, all).ok());
  EXPECT_EQ(ledger.unfinished(), 0u);
  ledger.Assign(second, 1);
  ledger.Assign(other, 2);
  const std::vector<render::SampleResult> some = {At(0, 0, 0), At(3, 3, 1)};
  ASSERT_TRUE(ledger.Record(1, some).ok());
  ASSERT_TRUE(ledger.Record(2, std::vector<render::SampleResult>{At(9, 1, 0)}).ok());
  ASSERT_TRUE(ledger.Record(1, std::vector<render::SampleResult>{At(1, 1, 1)}).ok());
  std::vector<render::SampleResult> merged;
  const std::vector<render::Tile> back = ledger.Release(1, &merged);
  ASSERT_EQ(back.size(), 1u);
  EXPECT_EQ(back[0].x0, 0);
  ASSERT_EQ(merged.size(), 3u) << "the first tile's samples are not given back";
  for (const render::SampleResult& s : merged) EXPECT_LT(s.pixel % kWidth, 4u);
  EXPECT_EQ(ledger.unfinished(), 1u);
}

// A sample sent twice (with another never sent, the count would still come out right) is an
// error naming the sender, and the tile does not finish.
TEST(TileLedger, ASampleSentTwiceIsAnError) {
  const render::Tile tile{4, 8, 8, 12, 1, 3};
  TileLedger ledger(kWidth, 4);
  ledger.Assign(tile, 2);
  std::vector<render::SampleResult> all = AllOf(tile);
  all.back() = all.front();
  const Status s = ledger.Record(2, all);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("rank 2 sent sample 1 of pixel 132 twice"), std::string::npos)
      << s.message();
  EXPECT_EQ(ledger.unfinished(), 1u);
}

TEST(TileLedger, SamplesOfAnotherSlavesTileOrOutsideItAreErrors) {
  const render::Tile tile{4, 8, 8, 12, 1, 3};
  TileLedger ledger(kWidth, 4);
  ledger.Assign(tile, 1);
  const render::SampleResult outside[] = {At(3, 8, 1)}, sample0[] = {At(4, 8, 0)},
                             mine[] = {At(4, 8, 1)};
  EXPECT_FALSE(ledger.Record(1, outside).ok());
  EXPECT_FALSE(ledger.Record(1, sample0).ok());
  EXPECT_FALSE(ledger.Record(2, mine).ok());
  EXPECT_TRUE(ledger.Record(1, mine).ok());
}

// A lost slave's unfinished tile comes back whole, with the samples it had sent; given to
// another slave, every sample may come again.
TEST(TileLedger, AReleasedTileIsGivenBackWithItsSamples) {
  const render::Tile tile{4, 8, 8, 12, 1, 3};
  TileLedger ledger(kWidth, 4);
  ledger.Assign(tile, 1);
  const std::vector<render::SampleResult> all = AllOf(tile);
  ASSERT_TRUE(ledger.Record(1, std::span(all).first(5)).ok());
  std::vector<render::SampleResult> merged;
  const std::vector<render::Tile> back = ledger.Release(1, &merged);
  ASSERT_EQ(back.size(), 1u);
  EXPECT_EQ(back[0], tile);
  EXPECT_EQ(merged.size(), 5u);
  EXPECT_EQ(ledger.unfinished(), 0u);
  ledger.Assign(tile, 3);
  ASSERT_TRUE(ledger.Record(3, all).ok());
  EXPECT_EQ(ledger.unfinished(), 0u);
}

// Each rank's tiles are looked up among its own (the ledger keeps them per rank): samples of
// three ranks' tiles, interleaved, finish each tile once; a rank's samples of a tile another rank
// holds, or from a rank never given one, are errors; releasing one rank leaves the others'.
TEST(TileLedger, RanksTilesAreKeptApart) {
  const render::Tile a{0, 0, 4, 4, 0, 2}, b{4, 0, 8, 4, 0, 2}, c{8, 0, 12, 4, 0, 2},
                     d{0, 4, 4, 8, 0, 2};
  TileLedger ledger(kWidth, 2);
  ledger.Assign(a, 1);
  ledger.Assign(b, 5);
  ledger.Assign(c, 1);
  ledger.Assign(d, 3);
  const std::vector<render::SampleResult> of_a = AllOf(a), of_b = AllOf(b), of_c = AllOf(c);
  for (size_t i = 0; i < of_a.size(); ++i) {
    if (i + 1 < of_a.size()) {  // rank 1 alternates between its two tiles
      ASSERT_TRUE(ledger.Record(1, std::span(&of_a[i], 1)).ok());
      ASSERT_TRUE(ledger.Record(1, std::span(&of_c[i], 1)).ok());
    }
    ASSERT_TRUE(ledger.Record(5, std::span(&of_b[i], 1)).ok());
  }
  EXPECT_EQ(ledger.unfinished(), 3u);  // b finished; a and c one sample short, d untouched
  EXPECT_FALSE(ledger.Record(3, std::span(&of_a.back(), 1)).ok());   // rank 1's tile
  EXPECT_FALSE(ledger.Record(2, std::span(&of_a.back(), 1)).ok());   // never given a tile
  EXPECT_FALSE(ledger.Record(-1, std::span(&of_a.back(), 1)).ok());  // not a rank
  std::vector<render::SampleResult> merged;
  const std::vector<render::Tile> back = ledger.Release(1, &merged);
  EXPECT_EQ(back.size(), 2u);
  EXPECT_EQ(merged.size(), 2 * (of_a.size() - 1));
  EXPECT_EQ(ledger.unfinished(), 1u);  // d, rank 3's
  EXPECT_TRUE(ledger.Release(7, &merged).empty());
  const std::vector<render::SampleResult> of_d = AllOf(d);
  ASSERT_TRUE(ledger.Record(3, of_d).ok());
  EXPECT_EQ(ledger.unfinished(), 0u);
}

}  // namespace
}  // namespace raystack::master
