#pragma once
// How a frame is rendered progressively: as passes of a few samples per pixel over the whole
// image (pass 1 = sample 0, then doubling, or a fixed number per pass), so every pixel has k
// samples before any has many more, and the image can be stopped after any pass (--spp,
// --time-limit, --target-error). A pass is handed out as one or more *sweeps* of tiles; in
// priority order the first pass is split into sweeps by the priority matrix (1/256 of the
// pixels, spread evenly, then 3/256, 12/256, ...), so a coarse full frame exists early; a
// round's tiles are larger in proportion, so each holds about a full tile's pixels.
// Random numbers depend only on (seed, pixel, sample), so the plan never changes the image.

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "common/render/tiles.h"

namespace raystack::render {

enum class PixelOrder { kPriority, kScanline };
const char* PixelOrderName(PixelOrder order);
Expected<PixelOrder> ParsePixelOrder(const std::string& name);

struct SampleRange {
  uint32_t begin = 0, end = 0;  // [begin, end)
};

// The passes covering samples [0, spp): pass_spp 0 gives 1, 1, 2, 4, ... samples per pixel
// (the sample count doubles with each pass); otherwise pass_spp per pass (the last may be
// smaller).
std::vector<SampleRange> PassRanges(uint32_t spp, uint32_t pass_spp);

// A sweep's tiles are made when it is handed out (FramePlan::Tiles), not with the plan: a plan
// of 16k x 16k pixels and 4,096 samples a pixel is 64 M tiles (1.9 GB, 30 GB at 65,535
// samples), where its sweeps share one grid of rectangles.
struct Sweep {
  // Its tiles: the grid's, in order, each given the sweep's samples [sample_begin, sample_end)
  // (the grid's own when sample_end is 0) and pixel ranks [rank_begin, rank_end), less those
  // left with no sample and those `kept` leaves out.
  std::shared_ptr<const std::vector<Tile>> grid;
  std::shared_ptr<const std::vector<bool>> kept;  // by grid tile; null: every one (FramePlan::Count)
  uint32_t sample_begin = 0, sample_end = 0;
  uint16_t rank_begin = 0, rank_end = kPriorityPeriod * kPriorityPeriod;
  uint32_t pass = 0;        // index into the passes (a pass may take several sweeps)
  bool pass_end = false;    // the last sweep of its pass: after it, every pixel has
                            // passes[pass].end samples
  uint64_t tile_count = 0, samples = 0;  // of its tiles, as FramePlan::Count found them
};

struct FramePlan {
  int width = 0, height = 0;
  std::vector<SampleRange> passes;
  std::vector<Sweep> sweeps;

  uint32_t spp() const { return passes.empty() ? 0 : passes.back().end; }
  uint64_t total_samples() const {
    return static_cast<uint64_t>(width) * static_cast<uint64_t>(height) * spp();
  }
  // The samples its tiles stand for: total_samples(), less what --resume dropped (the tiles a
  // checkpoint finished), the work a progress bar counts to.
  uint64_t samples_to_render() const;
  // Sweep `i`'s tiles, in the order they should be handed out.
  std::vector<Tile> Tiles(size_t i) const;
  // Calls visit(tile) for each of sweep `i`'s tiles in that order, without making the list.
  void ForEachTile(size_t i, const std::function<void(const Tile&)>& visit) const;
  // Adds a sweep of `tiles` as they are (a frame of given tiles, tests), counted; tiles with no
  // sample are left out, as from every sweep.
  void AddSweep(std::vector<Tile> tiles, uint32_t pass, bool pass_end);
  // Leaves out the tiles `keep` refuses (--resume: those a checkpoint finished), noted once per
  // grid and pixel ranks (a bit a tile: `keep` must look at a tile's rectangle and ranks, not its
  // samples, and is not kept), and sets every sweep's tile_count and samples.
  void Keep(const std::function<bool(const Tile&)>& keep);
  // Sets every sweep's tile_count and samples (MakeFramePlan does; sweeps added by hand need it).
  void Count();

 private:
  // A sweep's grid tile `t` given its samples and ranks.
  static Tile Placed(const Sweep& sweep, Tile t);
  void CountSweep(size_t i);
};

// The most samples one tile of a plan holds (pixels x samples per pixel).
inline constexpr uint32_t kMaxTileSamples = 16384;

// Priority: Hilbert-ordered tiles, first pass in priority-matrix rounds (unless
// `coarse_rounds` is false: then one sweep), pixels within a tile by priority. Scanline: tiles
// and pixels in scanline order, every pass one sweep. Each round sweeps the whole frame, so
// with a block cache smaller than the blocks the frame needs every round loads them again:
// the caller turns the rounds off out of core (master/frame_steps.h, --coarse-rounds).
FramePlan MakeFramePlan(int width, int height, int tile_size, uint32_t spp, uint32_t pass_spp,
                        PixelOrder order, bool coarse_rounds = true);

// Samples a tile stands for (its pixels in its rank range times its samples); `spp` resolves a
// tile whose sample_end is 0 (the whole frame's samples).
uint64_t TileSamples(const Tile& tile, uint32_t spp);

}  // namespace raystack::render
