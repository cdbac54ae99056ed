#pragma once
// Which slave renders which tile of a frame, and the samples merged from each tile that is
// not finished yet. A slave that is lost or fails leaves tiles half done: the master takes
// their samples back out of the film (Film::Unmerge) and hands the tiles to others, so the
// image is exactly the image of a run without the loss. A tile (a rectangle, a sample range and
// a pixel-rank range: common/render/frame_plan.h) is finished once all of its samples have
// come; only then are its kept samples dropped, so what is kept is bounded by the tiles in
// flight. Checking samples against it also refuses a slave's samples it was not asked for.
// Not thread-safe: the master's one loop owns it.

#include <cstdint>
#include <span>
#include <vector>

#include "common/base/status.h"
#include "common/render/sample_result.h"
#include "common/render/tiles.h"

namespace raystack::master {

class TileLedger {
 public:
  // For a `width`-pixel-wide image of `spp` samples per pixel (what a tile's sample_end 0
  // stands for).
  TileLedger(int width, uint32_t spp) : width_(width), spp_(spp) {}

  // Slave `rank` has been given `tile`.
  void Assign(const render::Tile& tile, int rank);
  // Samples from `rank`: each must belong to a tile it was given and has not finished, and
  // come once (a sample merged twice would count twice in the film and finish its tile with
  // another missing). Kept while their tile is unfinished.
  Status Record(int rank, std::span<const render::SampleResult> samples);
  // `rank` is gone: the tiles it was given and did not finish (returned), and its samples of
  // them (appended to `merged`, to be taken back out of the film).
  std::vector<render::Tile> Release(int rank, std::vector<render::SampleResult>* merged);

  // Tiles handed out and not finished.
  size_t unfinished() const { return unfinished_; }

 private:
  struct Entry {
    render::Tile tile;
    uint64_t received = 0, expected = 0;
    std::vector<render::SampleResult> kept;
    // A bit per (pixel of the rectangle, sample of the range): which have come. At most a few
    // KB for a tile of the frame plan (kMaxTileSamples), more for the sparse first rounds' wider
    // rectangles.
    std::vector<uint64_t> seen;
  };
  // The bit of sample `s` (which `e.tile` holds) in `e.seen`.
  size_t SeenBit(const Entry& e, const render::SampleResult& s) const;
  bool Holds(const render::Tile& t, const render::SampleResult& s) const;
  // One rank's tiles in flight: a few per ray thread, searched linearly, starting where its
  // last sample was found (a batch's samples come tile by tile, so the search usually ends
  // there at once).
  struct RankTiles {
    std::vector<Entry> in_flight;
    size_t last = 0;
  };
  // Indexed by rank. Once one list over every rank: a sample not in its rank's last tile was
  // searched for among all of them, and at 64 slaves of 64 threads (8,192 tiles in flight) the
  // master merged ~0.4 M samples a second instead of ~9 M (a scale review's measure).
  std::vector<RankTiles> ranks_;
  // Finished tiles' `kept` vectors, cleared, for the next tiles: their memory is mapped already
  // (growing a new one for every tile, by doubling, was a quarter of the master's CPU time with
  // its page faults and copies, at 32 samples per pixel).
  std::vector<std::vector<render::SampleResult>> spare_kept_;
  const int width_;
  const uint32_t spp_;
  size_t unfinished_ = 0;
};

}  // namespace raystack::master
