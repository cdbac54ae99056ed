#pragma once
// --resume: continue a frame from its last EXR checkpoint (written with --checkpoint-s, with
// per-pixel sample counts). A tile whose every pixel has all `spp` samples in the checkpoint is
// kept as the checkpoint has it; every other tile is rendered again from its first sample
// (random numbers are a hash of pixel and sample, so it renders exactly as it would have).
// The resumed image therefore equals an uninterrupted run's bit for bit.

#include <cstdint>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "common/image/image_layers.h"
#include "common/render/film.h"
#include "common/render/tiles.h"

namespace raystack::master {

struct ResumePlan {
  std::vector<render::Tile> to_render;  // in the order given
  std::vector<uint32_t> kept_pixels;    // pixels of finished tiles, taken from the checkpoint
  image::ImageLayers checkpoint;        // empty when there is none
  size_t kept_tiles = 0;
};

// Reads `exr` (a missing file: nothing to resume, every tile is rendered). An EXR of another
// size, or without per-pixel sample counts, is an error naming it.
Expected<ResumePlan> PlanResume(const std::string& exr, int width, int height, uint32_t spp,
                                std::vector<render::Tile> tiles);

// Puts the kept pixels into `film`.
inline void ApplyResume(const ResumePlan& plan, render::Film* film) {
  if (!plan.kept_pixels.empty()) film->Restore(plan.checkpoint, plan.kept_pixels);
}

}  // namespace raystack::master
