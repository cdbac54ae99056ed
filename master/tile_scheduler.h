#pragma once
// Which tile a slave gets next (thesis VI.2: tiles on demand, each near that slave's previous
// ones, since its block cache is warm there). The frame's tiles in Hilbert order are cut into
// one contiguous span per slave; a slave takes the next tile of its own span, and once that is
// used up, the last tile of the span with the most left (the far end of another slave's
// region, where it will arrive last). Not thread-safe: the master's one loop owns it.

#include <cstdint>
#include <vector>

#include "common/render/tiles.h"

namespace raystack::master {

class TileScheduler {
 public:
  TileScheduler(std::vector<render::Tile> tiles, int slaves);
  // The index of the next tile for `slave` (0-based), false when none is left to hand out.
  bool Next(int slave, size_t* index);
  const render::Tile& tile(size_t index) const { return tiles_[index]; }
  const std::vector<render::Tile>& tiles() const { return tiles_; }
  uint64_t handed_out() const { return handed_out_; }
  bool exhausted() const {
    for (const Span& s : spans_)
      if (s.begin < s.end) return false;
    return true;
  }

 private:
  struct Span {
    size_t begin, end;  // tiles_[begin, end) not handed out yet
  };
  std::vector<render::Tile> tiles_;
  std::vector<Span> spans_;
  uint64_t handed_out_ = 0;
};

inline TileScheduler::TileScheduler(std::vector<render::Tile> tiles, int slaves)
    : tiles_(std::move(tiles)) {
  const size_t n = tiles_.size(), s = static_cast<size_t>(slaves > 0 ? slaves : 1);
  for (size_t i = 0; i < s; ++i) spans_.push_back({i * n / s, (i + 1) * n / s});
}

inline bool TileScheduler::Next(int slave, size_t* index) {
  Span& own = spans_[static_cast<size_t>(slave) % spans_.size()];
  if (own.begin < own.end) {
    *index = own.begin++;
    ++handed_out_;
    return true;
  }
  Span* richest = nullptr;
  for (Span& s : spans_)
    if (s.end > s.begin && (!richest || s.end - s.begin > richest->end - richest->begin))
      richest = &s;
  if (!richest) return false;
  *index = --richest->end;
  ++handed_out_;
  return true;
}

}  // namespace raystack::master
