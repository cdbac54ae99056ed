#pragma once
// --resume: continue a frame from its last EXR checkpoint (written with --checkpoint-s, with
// per-pixel sample counts). A pixel the checkpoint holds with all `spp` samples is kept as the
// checkpoint has it (Film::Restore); every tile that holds a pixel with fewer is rendered
// again from its first sample (random numbers are a hash of pixel and sample, so it renders
// exactly as it would have; the kept pixels it also covers stay as restored). The resumed
// image therefore equals an uninterrupted run's bit for bit.

#include <cstdint>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "common/image/image_layers.h"
#include "common/render/film.h"
#include "common/render/frame_plan.h"
#include "common/render/tiles.h"

namespace raystack::master {

struct ResumePlan {
  int width = 0;
  std::vector<uint8_t> finished;      // by pixel; empty when there is no checkpoint
  std::vector<uint32_t> kept_pixels;  // the finished ones
  image::ImageLayers checkpoint;
  // Whether `tile` holds a pixel still to render.
  bool Needs(const render::Tile& tile) const;
};

// Reads `exr` (a missing file: nothing to resume, every tile is rendered). An EXR of another
// size, without per-pixel sample counts, or rendered from another scene, camera or setting
// (its provenance is not `provenance`) is an error naming it.
Expected<ResumePlan> PlanResume(const std::string& exr, int width, int height, uint32_t spp,
                                const std::string& provenance);

// Drops from `plan` the tiles whose pixels are all finished; returns how many tiles are left.
// The samples the dropped tiles stood for, total_samples() - samples_to_render(), are the ones
// the run does not render (a finished pixel in a tile still to render is rendered again).
size_t DropFinishedTiles(const ResumePlan& resume, render::FramePlan* plan);

// Puts the kept pixels into `film`.
inline void ApplyResume(const ResumePlan& plan, render::Film* film) {
  if (!plan.kept_pixels.empty()) film->Restore(plan.checkpoint, plan.kept_pixels);
}

}  // namespace raystack::master
