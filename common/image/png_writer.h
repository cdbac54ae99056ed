#pragma once
// An 8-bit PNG quick look at a render, for browsers and chat; the EXR stays the real output.

#include <cstdint>
#include <string>

#include "common/base/status.h"
#include "common/image/image_layers.h"
#include "common/base/output_file.h"  // CheckWritable, for the callers of WritePng

namespace raystack::image {

// Tone-mapped 8-bit sRGB quick-look: rgb * 2^exposure, clamped, sRGB transfer curve. Atomic like
// WriteExr. Alpha is not written (an RGB PNG); NaN shows as black.
Status WritePng(const std::string& path, const ImageLayers& image, float exposure = 0);
}  // namespace raystack::image
