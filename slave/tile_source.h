#pragma once
// Where ray threads get their next image tile: in one process, the frame's tiles in order; in
// a distributed run, the master's assignments. One virtual call per tile.

#include <atomic>
#include <cstdint>
#include <vector>

namespace raystack::slave {

struct Tile {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // [x0, x1) x [y0, y1)
  int pixels() const { return (x1 - x0) * (y1 - y0); }
};

class TileSource {
 public:
  virtual ~TileSource() = default;
  // The next tile for ray thread `thread`, false when the frame has no more. Thread-safe.
  virtual bool Next(uint32_t thread, Tile* tile) = 0;
};

// The frame cut into size x size tiles, handed out in scanline order of tiles.
class GridTileSource final : public TileSource {
 public:
  GridTileSource(int width, int height, int size) {
    for (int y = 0; y < height; y += size)
      for (int x = 0; x < width; x += size)
        tiles_.push_back({x, y, x + size < width ? x + size : width, y + size < height ? y + size : height});
  }
  bool Next(uint32_t, Tile* tile) override {
    const size_t i = next_.fetch_add(1);
    if (i >= tiles_.size()) return false;
    *tile = tiles_[i];
    return true;
  }

 private:
  std::vector<Tile> tiles_;
  std::atomic<size_t> next_{0};
};

}  // namespace raystack::slave
