#pragma once
// What the live preview shows besides the image: where the render stands, how fast it goes,
// and which tiles each slave is working on. Filled by the render loop and handed to
// PreviewServer::Publish; plain data.

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "common/render/tiles.h"

namespace raystack::master::preview {

// The tiles one rank has been given this frame (the preview drops those the film shows done).
struct RankTiles {
  int rank = 0;  // 0 in a one-process run (the local engine)
  std::vector<render::Tile> tiles;
  std::string dropped;  // why the slave was dropped from the job ("lost: ..."); empty: working
};

struct PreviewStatus {
  uint32_t frame = 0, frames = 1;  // frame index, and how many the scene has
  uint32_t last_frame = 0;         // the job's last (--frames renders part of the scene's)
  uint64_t samples_done = 0;       // samples merged into the film so far
  uint64_t samples_restored = 0;   // from a checkpoint (--resume): done, but not in the rate
  uint64_t samples_total = 0;      // width * height * spp
  int spp = 1;                     // samples per pixel the frame asks for
  double elapsed_seconds = 0;      // since the frame started
  // NaN when not known (yet): while rendering, from the rays each pixel batch reports; at the
  // frame's end, the engines' totals.
  double rays_per_second = std::numeric_limits<double>::quiet_NaN();
  // The current error estimate of the image (from per-pixel variance; filled by the
  // convergence log when it exists); NaN shows as "—".
  double error_estimate = std::numeric_limits<double>::quiet_NaN();
  bool finished = false;           // the frame is complete (the image is final)
  bool failed = false;             // the job failed in this frame (see note): no time left
  bool interrupted = false;        // SIGINT or SIGTERM ended the job in this frame (see note)
  // What ended the frame early or went wrong, as the terminal says it ("stopped: ...",
  // "failed: ...", "interrupted (SIGINT): ..."); empty for none. Shown on the page until replaced.
  std::string note;
  std::vector<RankTiles> tiles;    // by rank
};

// The status as the JSON text message the page reads. `covered` (per pixel sample counts of
// the same frame, or empty) lets tiles whose pixels all have `spp` samples be left out: they
// are no longer in flight.
std::string StatusJson(const PreviewStatus& status, int width,
                       const std::vector<uint32_t>& counts);

}  // namespace raystack::master::preview
