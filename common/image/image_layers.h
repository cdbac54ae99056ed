#pragma once
// A rendered frame with everything an engine produces per pixel: colour and the auxiliary
// layers (depth, normal, albedo for denoisers; sample counts and variance for adaptive
// sampling). Plain data; not synchronised (an engine writes disjoint pixels or merges tiles).

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace raystack::image {

struct ImageLayers {
  int width = 0, height = 0;
  std::vector<float> rgba;        // 4 per pixel, row-major, row 0 at the top
  std::vector<float> z;           // 1 per pixel; +inf where the primary ray missed
  std::vector<float> normal;      // 3 per pixel
  std::vector<float> albedo;      // 3 per pixel
  std::vector<uint32_t> samples;  // per-pixel sample count
  std::vector<float> variance;    // per-pixel variance estimate of the pixel mean (luminance)
  // What rendered it (scene, camera, settings), as text; the EXR's "raystack.provenance"
  // attribute. --resume compares it with the run's. Empty: unknown (not written).
  std::string provenance;
  // Written with a provenance, as the EXR's "raystack.state": "partial" for a frame not
  // finished (a checkpoint, or what an interrupted or failed run saved: --resume continues
  // it), "complete" for a frame's final image. Read back as true only for "partial".
  bool partial = false;
  // Why a stop rule (--time-limit, --target-error) ended the frame before its spp, as the
  // terminal said it; the EXR's "raystack.stopped" (a complete frame whose pixels have fewer
  // samples than its provenance's spp). Empty: not stopped early.
  std::string stopped;

  void Resize(int w, int h);  // allocates all layers (z filled with +inf, rest 0)

  size_t pixel_count() const { return static_cast<size_t>(width) * static_cast<size_t>(height); }
  // Index of pixel (x, y) in a layer with one value per pixel (multiply by 3 or 4 for the others).
  size_t PixelIndex(int x, int y) const {
    return static_cast<size_t>(y) * static_cast<size_t>(width) + static_cast<size_t>(x);
  }
};

}  // namespace raystack::image
