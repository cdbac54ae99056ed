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

// The frame cut into size x size tiles, handed out along a Hilbert curve: consecutive tiles
// are neighbours on screen, so they see mostly the same blocks and a small cache is reused
// instead of reloaded (scanline order sweeps the whole width between two visits of a block).
class GridTileSource final : public TileSource {
 public:
  GridTileSource(int width, int height, int size) {
    const uint32_t nx = static_cast<uint32_t>((width + size - 1) / size);
    const uint32_t ny = static_cast<uint32_t>((height + size - 1) / size);
    uint32_t side = 1;
    while (side < nx || side < ny) side *= 2;
    for (uint64_t d = 0; d < uint64_t{side} * side; ++d) {
      uint32_t tx, ty;
      HilbertPoint(side, static_cast<uint32_t>(d), &tx, &ty);
      if (tx >= nx || ty >= ny) continue;
      const int x = static_cast<int>(tx) * size, y = static_cast<int>(ty) * size;
      tiles_.push_back({x, y, x + size < width ? x + size : width, y + size < height ? y + size : height});
    }
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
