#include "master/resume.h"

#include <sys/stat.h>

#include "common/base/log.h"
#include "common/image/exr_io.h"

namespace raystack::master {

Expected<ResumePlan> PlanResume(const std::string& exr, int width, int height, uint32_t spp,
                                std::vector<render::Tile> tiles) {
  ResumePlan plan;
  struct stat st;
  if (stat(exr.c_str(), &st) != 0) {
    plan.to_render = std::move(tiles);
    return plan;
  }
  Expected<image::ImageLayers> read = image::ReadExr(exr);
  if (!read.ok()) return read.status();
  if (read->width != width || read->height != height)
    return Status::Error(StrFormat("%s: the checkpoint is %dx%d, this frame %dx%d: not a "
                                   "checkpoint of this frame", exr.c_str(), read->width,
                                   read->height, width, height));
  if (read->samples.empty())
    return Status::Error(exr + ": no per-pixel sample counts (samples layer): not a raystack "
                         "checkpoint, cannot resume from it");
  for (const render::Tile& t : tiles) {
    bool finished = true;
    for (int y = t.y0; y < t.y1 && finished; ++y)
      for (int x = t.x0; x < t.x1 && finished; ++x)
        finished = read->samples[read->PixelIndex(x, y)] >= spp;
    if (!finished) {
      plan.to_render.push_back(t);
      continue;
    }
    ++plan.kept_tiles;
    for (int y = t.y0; y < t.y1; ++y)
      for (int x = t.x0; x < t.x1; ++x)
        plan.kept_pixels.push_back(static_cast<uint32_t>(read->PixelIndex(x, y)));
  }
  plan.checkpoint = std::move(*read);
  return plan;
}

}  // namespace raystack::master
