#pragma once
// Who renders which tile of a frame, and the samples merged from each tile that is not finished
// yet. A slave that is lost or fails leaves tiles half done: the master takes their samples back
// out of the film (Film::Unmerge) and hands the tiles to others, so the image is exactly the
// image of a run without the loss. A tile is finished once all of its pixels x spp samples
// have come; only then are its kept samples dropped, so what is kept is bounded by the tiles
// in flight. Checking samples against it also refuses a slave's samples for pixels it was not
// given. Not thread-safe: the master's one loop owns it.

#include <cstdint>
#include <span>
#include <vector>

#include "common/base/status.h"
#include "common/render/sample_result.h"
#include "common/render/tiles.h"

namespace raystack::master {

class TileLedger {
 public:
  // `tiles` cover the width x height image without overlap; each pixel gets `spp` samples.
  TileLedger(const std::vector<render::Tile>& tiles, int width, int height, uint32_t spp);

  // Slave `rank` has been given tile `index`.
  void Assign(size_t index, int rank);
  // Samples from `rank`: each must be of a pixel of a tile it was given and not finished, with
  // a sample index below spp. Kept while their tile is unfinished.
  Status Record(int rank, std::span<const render::SampleResult> samples);
  // `rank` is gone: the tiles it was given and did not finish (returned), and its samples of
  // them (appended to `merged`, to be taken back out of the film). They are unassigned.
  std::vector<size_t> Release(int rank, std::vector<render::SampleResult>* merged);

  size_t unfinished() const { return unfinished_; }
  // Tiles being rendered by `rank` now (given, not finished).
  std::vector<size_t> InFlight(int rank) const;

 private:
  static constexpr int kNobody = 0;  // rank 0 is the master, never a tile's renderer
  struct Entry {
    int rank = kNobody;
    uint64_t received = 0, expected = 0;
    std::vector<render::SampleResult> kept;
  };
  std::vector<Entry> entries_;
  std::vector<uint32_t> tile_of_pixel_;
  const uint32_t spp_;
  size_t unfinished_;
};

}  // namespace raystack::master
