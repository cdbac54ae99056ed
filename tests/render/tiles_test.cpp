// The order a tile's pixels are fed in: ForEachTilePixel lists them rank by rank without a sort,
// and must give exactly what a stable sort by descending priority gives.

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <tuple>
#include <vector>

#include "common/render/tiles.h"

namespace raystack::render {
namespace {

using Pixels = std::vector<std::pair<int, int>>;

Pixels Listed(const Tile& tile, bool by_priority) {
  Pixels out;
  ForEachTilePixel(tile, by_priority, [&](int x, int y) { out.push_back({x, y}); });
  return out;
}

// The reference: the tile's pixels in scanline order, stable-sorted by descending priority.
Pixels Sorted(const Tile& tile) {
  std::vector<std::tuple<uint16_t, int, int>> all;
  for (int y = tile.y0; y < tile.y1; ++y)
    for (int x = tile.x0; x < tile.x1; ++x)
      if (tile.HasRank(x, y)) all.push_back({PixelPriority(x, y), x, y});
  std::stable_sort(all.begin(), all.end(),
                   [](const auto& a, const auto& b) { return std::get<0>(a) > std::get<0>(b); });
  Pixels out;
  for (const auto& [priority, x, y] : all) out.push_back({x, y});
  return out;
}

TEST(RankPositions, InvertPixelRank) {
  for (int rank = 0; rank < kPriorityPeriod * kPriorityPeriod; ++rank) {
    const RankPosition at = kRankPositions[static_cast<size_t>(rank)];
    EXPECT_EQ(PixelRank(at.x, at.y), rank);
  }
}

TEST(ForEachTilePixel, ByPriorityIsAStableSortByDescendingPriority) {
  std::mt19937 random(7);
  auto pick = [&](int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(random); };
  for (int i = 0; i < 500; ++i) {
    Tile tile;
    tile.x0 = pick(0, 70);
    tile.y0 = pick(0, 70);
    tile.x1 = tile.x0 + pick(1, 40);
    tile.y1 = tile.y0 + pick(1, 40);
    if (i % 2) {  // a round's rank range, sometimes empty or past the last rank
      tile.rank_begin = static_cast<uint16_t>(pick(0, 260));
      tile.rank_end = static_cast<uint16_t>(pick(0, 300));
    }
    ASSERT_EQ(Listed(tile, true), Sorted(tile)) << "tile " << tile.x0 << "," << tile.y0 << " - "
                                                << tile.x1 << "," << tile.y1 << " ranks "
                                                << tile.rank_begin << "-" << tile.rank_end;
  }
}

TEST(TilePixelCount, CountsThePixelsOfTheRankRange) {
  std::mt19937 random(11);
  auto pick = [&](int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(random); };
  for (int i = 0; i < 500; ++i) {
    Tile tile;
    tile.x0 = pick(0, 70);
    tile.y0 = pick(0, 70);
    tile.x1 = tile.x0 + pick(0, 60);
    tile.y1 = tile.y0 + pick(0, 60);
    if (i % 4) {
      tile.rank_begin = static_cast<uint16_t>(pick(0, 260));
      tile.rank_end = static_cast<uint16_t>(pick(0, 300));
    }
    int64_t counted = 0;
    for (int y = tile.y0; y < tile.y1; ++y)
      for (int x = tile.x0; x < tile.x1; ++x) counted += tile.HasRank(x, y) ? 1 : 0;
    ASSERT_EQ(TilePixelCount(tile), counted) << "tile " << tile.x0 << "," << tile.y0 << " - "
                                             << tile.x1 << "," << tile.y1 << " ranks "
                                             << tile.rank_begin << "-" << tile.rank_end;
  }
}

TEST(ForEachTilePixel, ScanlineOrderListsTheTilesPixelsRowByRow) {
  Tile tile{3, 5, 7, 8};
  tile.rank_begin = 0;
  tile.rank_end = 64;
  Pixels expected;
  for (int y = 5; y < 8; ++y)
    for (int x = 3; x < 7; ++x)
      if (PixelRank(x, y) < 64) expected.push_back({x, y});
  EXPECT_EQ(Listed(tile, false), expected);
  EXPECT_FALSE(expected.empty());
}

}  // namespace
}  // namespace raystack::render
