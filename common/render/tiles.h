#pragma once
// Image tiles and the order they are rendered in, shared by the master (which hands them out)
// and the slaves (which render them). Tiles follow a Hilbert curve over the tile grid:
// consecutive tiles are neighbours on screen, so they see mostly the same blocks and a small
// cache is reused instead of reloaded (scanline order sweeps the whole width between two
// visits of a block).

#include <cstdint>
#include <vector>

#include "common/render/pixel_priority.h"

namespace raystack::render {

// A piece of work: a rectangle of pixels, the samples [sample_begin, sample_end) of each, and
// only the pixels whose rank in the priority matrix (pixel_priority.h) is in [rank_begin,
// rank_end), so a first pass can visit the whole frame sparsely before filling it in.
struct Tile {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // [x0, x1) x [y0, y1)
  uint32_t sample_begin = 0, sample_end = 0;  // sample_end 0: every sample of the frame's spp
  uint16_t rank_begin = 0, rank_end = 256;     // every pixel by default
  int pixels() const { return (x1 - x0) * (y1 - y0); }
  // Every pixel of the rectangle is the tile's, whatever its rank.
  bool all_ranks() const { return rank_begin == 0 && rank_end >= kPriorityPeriod * kPriorityPeriod; }
  // Pixel (x, y) of the rectangle is the tile's: its rank is in the tile's range.
  bool HasRank(int x, int y) const {
    if (all_ranks()) return true;
    const uint16_t rank = PixelRank(x, y);
    return rank >= rank_begin && rank < rank_end;
  }
  bool operator==(const Tile&) const = default;
};

namespace tiles_internal {
// The first coordinate at or after v0 (>= 0) that is congruent to b modulo the period.
constexpr int FirstFrom(int v0, int b) {
  return v0 + ((b - v0 % kPriorityPeriod) % kPriorityPeriod + kPriorityPeriod) % kPriorityPeriod;
}
// How many of [v0, v1) are congruent to b modulo the period.
constexpr int64_t CountFrom(int v0, int v1, int b) {
  const int first = FirstFrom(v0, b);
  return first < v1 ? (v1 - 1 - first) / kPriorityPeriod + 1 : 0;
}
}  // namespace tiles_internal

// How many pixels the tile holds (those of its rank range), rank by rank: O(ranks), not O(pixels),
// so a frame plan's large sparse round tiles are counted without visiting their pixels.
inline int64_t TilePixelCount(const Tile& tile) {
  if (tile.x1 <= tile.x0 || tile.y1 <= tile.y0) return 0;
  if (tile.all_ranks()) return int64_t{tile.x1 - tile.x0} * (tile.y1 - tile.y0);
  constexpr int kRanks = kPriorityPeriod * kPriorityPeriod;
  const int rank_end = tile.rank_end < kRanks ? tile.rank_end : kRanks;
  int64_t pixels = 0;
  for (int rank = tile.rank_begin; rank < rank_end; ++rank) {
    const RankPosition at = kRankPositions[static_cast<size_t>(rank)];
    pixels += tiles_internal::CountFrom(tile.x0, tile.x1, at.x) *
              tiles_internal::CountFrom(tile.y0, tile.y1, at.y);
  }
  return pixels;
}

// Calls f(x, y) for each pixel of `tile` (those of its rank range) in the order they should be
// done: by priority (rank by rank, the pixels of one rank in scanline order), or in scanline
// order. The same order as a stable sort of the tile's pixels by descending priority, without
// the sort: a round's sparse tile lists only its own pixels.
template <typename F>
void ForEachTilePixel(const Tile& tile, bool by_priority, F&& f) {
  if (!by_priority) {
    for (int y = tile.y0; y < tile.y1; ++y)
      for (int x = tile.x0; x < tile.x1; ++x)
        if (tile.HasRank(x, y)) f(x, y);
    return;
  }
  constexpr int kRanks = kPriorityPeriod * kPriorityPeriod, p = kPriorityPeriod;
  const int rank_end = tile.rank_end < kRanks ? tile.rank_end : kRanks;
  for (int rank = tile.rank_begin; rank < rank_end; ++rank) {
    const RankPosition at = kRankPositions[static_cast<size_t>(rank)];
    for (int y = tiles_internal::FirstFrom(tile.y0, at.y); y < tile.y1; y += p)
      for (int x = tiles_internal::FirstFrom(tile.x0, at.x); x < tile.x1; x += p) f(x, y);
  }
}

// Position `d` along a Hilbert curve filling a side x side grid (side a power of two).
inline void HilbertPoint(uint32_t side, uint32_t d, uint32_t* x, uint32_t* y) {
  *x = *y = 0;
  for (uint32_t s = 1; s < side; s *= 2) {
    const uint32_t rx = 1 & (d / 2), ry = 1 & (d ^ rx);
    if (ry == 0) {  // rotate the quadrant
      if (rx == 1) {
        *x = s - 1 - *x;
        *y = s - 1 - *y;
      }
      const uint32_t t = *x;
      *x = *y;
      *y = t;
    }
    *x += s * rx;
    *y += s * ry;
    d /= 4;
  }
}

// The frame cut into size x size tiles (cropped at the edges), in Hilbert order.
inline std::vector<Tile> HilbertTiles(int width, int height, int size) {
  std::vector<Tile> tiles;
  const uint32_t nx = static_cast<uint32_t>((width + size - 1) / size);
  const uint32_t ny = static_cast<uint32_t>((height + size - 1) / size);
  uint32_t side = 1;
  while (side < nx || side < ny) side *= 2;
  for (uint64_t d = 0; d < uint64_t{side} * side; ++d) {
    uint32_t tx, ty;
    HilbertPoint(side, static_cast<uint32_t>(d), &tx, &ty);
    if (tx >= nx || ty >= ny) continue;
    const int x = static_cast<int>(tx) * size, y = static_cast<int>(ty) * size;
    tiles.push_back({x, y, x + size < width ? x + size : width, y + size < height ? y + size : height});
  }
  return tiles;
}

// The frame cut into size x size tiles in scanline order (left to right, top to bottom), for
// comparing with the Hilbert order and the priority matrix.
inline std::vector<Tile> ScanlineTiles(int width, int height, int size) {
  std::vector<Tile> tiles;
  for (int y = 0; y < height; y += size)
    for (int x = 0; x < width; x += size)
      tiles.push_back({x, y, x + size < width ? x + size : width, y + size < height ? y + size : height});
  return tiles;
}

}  // namespace raystack::render
