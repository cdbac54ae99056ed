#include "common/image/png_writer.h"

#include <png.h>

#include <cmath>
#include <cstring>
#include <vector>

#include "common/image/srgb8.h"

namespace raystack::image {

Status WritePng(const std::string& path, const ImageLayers& image, float exposure) {
  if (image.width < 1 || image.height < 1)
    return Status::Error(path + ": cannot write an empty image (" + std::to_string(image.width) +
                         " x " + std::to_string(image.height) + ")");
  const size_t pixels = image.pixel_count();
  if (image.rgba.size() != 4 * pixels)
    return Status::Error(path + ": cannot write: layer rgba holds " +
                         std::to_string(image.rgba.size()) + " values, expected " +
                         std::to_string(4 * pixels));
  if (!std::isfinite(exposure))
    return Status::Error(path + ": cannot write: exposure must be finite");
  const float scale = std::exp2(exposure);
  static const Srgb8Encoder encoder;  // LinearToSrgb8 without a pow per channel
  std::vector<uint8_t> rgb(3 * pixels);
  for (size_t i = 0; i < pixels; ++i)
    for (size_t c = 0; c < 3; ++c) rgb[3 * i + c] = encoder.Encode(image.rgba[4 * i + c] * scale);

  Expected<AtomicOutput> output = AtomicOutput::Create(path);
  if (!output.ok()) return output.status();
  // libpng's simplified API: errors come back in png_image::message, no setjmp/longjmp across
  // C++ frames.
  png_image png;
  std::memset(&png, 0, sizeof png);
  png.version = PNG_IMAGE_VERSION;
  png.width = static_cast<png_uint_32>(image.width);
  png.height = static_cast<png_uint_32>(image.height);
  png.format = PNG_FORMAT_RGB;
  const int ok = png_image_write_to_file(&png, output->temp_path().c_str(), /*convert_to_8bit=*/0,
                                         rgb.data(), /*row_stride=*/0, /*colormap=*/nullptr);
  if (!ok) {
    const std::string message = png.message;
    png_image_free(&png);
    return Status::Error(path + ": cannot write PNG: " + message);
  }
  return output->Commit();
}

}  // namespace raystack::image
