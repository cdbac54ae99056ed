#include "common/render/frame_plan.h"

#include <algorithm>


namespace raystack::render {

const char* PixelOrderName(PixelOrder order) {
  return order == PixelOrder::kPriority ? "priority" : "scanline";
}

Expected<PixelOrder> ParsePixelOrder(const std::string& name) {
  if (name == "priority") return PixelOrder::kPriority;
  if (name == "scanline") return PixelOrder::kScanline;
  return Status::Error("--pixel-order must be priority or scanline, got '" + name + "'");
}

std::vector<SampleRange> PassRanges(uint32_t spp, uint32_t pass_spp) {
  std::vector<SampleRange> passes;
  uint32_t begin = 0;
  while (begin < spp) {
    // Doubling: 1, then as many samples as already done, so pass k ends at 2^k.
    const uint32_t size = pass_spp > 0 ? pass_spp : std::max(1u, begin);
    const uint32_t end = spp - begin > size ? begin + size : spp;
    passes.push_back({begin, end});
    begin = end;
  }
  return passes;
}

FramePlan MakeFramePlan(int width, int height, int tile_size, uint32_t spp, uint32_t pass_spp,
                        PixelOrder order, bool coarse_rounds) {
  FramePlan plan;
  plan.width = width;
  plan.height = height;
  plan.passes = PassRanges(spp, pass_spp);
  auto grid_of = [&](int size) {
    return std::make_shared<const std::vector<Tile>>(
        order == PixelOrder::kPriority ? HilbertTiles(width, height, size)
                                       : ScanlineTiles(width, height, size));
  };
  const std::shared_ptr<const std::vector<Tile>> grid = grid_of(tile_size);
  // Rounds of the first pass in priority order: ranks [0,1), [1,4), [4,16), [16,64),
  // [64,256): each round halves the spacing of the pixels done so far.
  constexpr uint16_t kRounds[] = {0, 1, 4, 16, 64, 256};
  // A round's tiles are larger by kRoundScale on a side, so each still holds about as many
  // pixels as a full tile: the sparse rounds are a few dozen tiles, not thousands of nearly
  // empty ones (each a request to the master and a feed).
  constexpr int kRoundScale[] = {16, 8, 4, 2, 1};
  // A tile holds at most kMaxTileSamples samples: a late pass of many samples per pixel is
  // handed out as several sweeps of a few samples each, so a stop rule never waits long for
  // the tiles in flight, and a ray thread's open samples stay bounded.
  const uint32_t tile_pixels = static_cast<uint32_t>(std::max(1, tile_size * tile_size));
  const uint32_t chunk = std::max(1u, kMaxTileSamples / tile_pixels);
  for (uint32_t p = 0; p < plan.passes.size(); ++p) {
    const bool split = order == PixelOrder::kPriority && coarse_rounds && p == 0;
    const int rounds = split ? 5 : 1;
    for (uint32_t begin = plan.passes[p].begin; begin < plan.passes[p].end; begin += chunk) {
      const uint32_t end = std::min(plan.passes[p].end, begin + chunk);
      for (int r = 0; r < rounds; ++r) {
        Sweep sweep;
        sweep.grid = split && kRoundScale[r] != 1 ? grid_of(tile_size * kRoundScale[r]) : grid;
        sweep.sample_begin = begin;
        sweep.sample_end = end;
        if (split) {
          sweep.rank_begin = kRounds[r];
          sweep.rank_end = kRounds[r + 1];
        }
        sweep.pass = p;
        sweep.pass_end = r + 1 == rounds && end == plan.passes[p].end;
        plan.sweeps.push_back(std::move(sweep));
      }
    }
  }
  plan.Count();
  return plan;
}

Tile FramePlan::Placed(const Sweep& sweep, Tile t) {
  if (sweep.sample_end > 0) {
    t.sample_begin = sweep.sample_begin;
    t.sample_end = sweep.sample_end;
  }
  if (sweep.rank_begin != 0 || sweep.rank_end != kPriorityPeriod * kPriorityPeriod) {
    t.rank_begin = sweep.rank_begin;
    t.rank_end = sweep.rank_end;
  }
  return t;
}

void FramePlan::ForEachTile(size_t i, const std::function<void(const Tile&)>& visit) const {
  const Sweep& sweep = sweeps[i];
  const uint32_t frame_spp = spp();
  const std::vector<Tile>& grid = *sweep.grid;
  for (size_t k = 0; k < grid.size(); ++k) {
    if (sweep.kept && !(*sweep.kept)[k]) continue;
    const Tile t = Placed(sweep, grid[k]);
    if (TileSamples(t, frame_spp) > 0) visit(t);
  }
}

std::vector<Tile> FramePlan::Tiles(size_t i) const {
  std::vector<Tile> tiles;
  tiles.reserve(sweeps[i].tile_count);
  ForEachTile(i, [&](const Tile& t) { tiles.push_back(t); });
  return tiles;
}

void FramePlan::AddSweep(std::vector<Tile> tiles, uint32_t pass, bool pass_end) {
  Sweep sweep;
  sweep.grid = std::make_shared<const std::vector<Tile>>(std::move(tiles));
  sweep.pass = pass;
  sweep.pass_end = pass_end;
  sweeps.push_back(std::move(sweep));
  CountSweep(sweeps.size() - 1);
}

void FramePlan::CountSweep(size_t i) {
  const uint32_t frame_spp = spp();
  uint64_t tiles = 0, samples = 0;
  ForEachTile(i, [&](const Tile& t) {
    ++tiles;
    samples += TileSamples(t, frame_spp);
  });
  sweeps[i].tile_count = tiles;
  sweeps[i].samples = samples;
}

void FramePlan::Keep(const std::function<bool(const Tile&)>& keep) {
  // Sweeps of one grid and one rank range (the passes' sweeps after the first) share their bits:
  // `keep` runs once per tile of each, not once per sweep.
  struct Noted {
    const std::vector<Tile>* grid;
    uint16_t rank_begin, rank_end;
    std::shared_ptr<const std::vector<bool>> bits;
  };
  std::vector<Noted> noted;
  for (size_t i = 0; i < sweeps.size(); ++i) {
    Sweep& sweep = sweeps[i];
    auto same = [&](const Noted& n) {
      return n.grid == sweep.grid.get() && n.rank_begin == sweep.rank_begin && n.rank_end == sweep.rank_end;
    };
    auto it = std::find_if(noted.begin(), noted.end(), same);
    if (it == noted.end()) {
      auto bits = std::make_shared<std::vector<bool>>(sweep.grid->size());
      for (size_t k = 0; k < sweep.grid->size(); ++k) (*bits)[k] = keep(Placed(sweep, (*sweep.grid)[k]));
      noted.push_back({sweep.grid.get(), sweep.rank_begin, sweep.rank_end, std::move(bits)});
      it = noted.end() - 1;
    }
    // (A sweep kept partly already, by an earlier call, keeps what both keep.)
    if (sweep.kept) {
      auto both = std::make_shared<std::vector<bool>>(*it->bits);
      for (size_t k = 0; k < both->size(); ++k) (*both)[k] = (*both)[k] && (*sweep.kept)[k];
      sweep.kept = std::move(both);
    } else {
      sweep.kept = it->bits;
    }
    CountSweep(i);
  }
}

void FramePlan::Count() {
  for (size_t i = 0; i < sweeps.size(); ++i) CountSweep(i);
}

uint64_t FramePlan::samples_to_render() const {
  uint64_t sum = 0;
  for (const Sweep& sweep : sweeps) sum += sweep.samples;
  return sum;
}

uint64_t TileSamples(const Tile& tile, uint32_t spp) {
  const uint32_t end = tile.sample_end == 0 ? spp : tile.sample_end;
  if (end <= tile.sample_begin) return 0;
  return static_cast<uint64_t>(TilePixelCount(tile)) * (end - tile.sample_begin);
}

}  // namespace raystack::render
