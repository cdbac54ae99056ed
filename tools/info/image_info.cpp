#include "tools/info/image_info.h"

#include <algorithm>
#include <cstdio>

#include "common/image/exr_io.h"

namespace raystack::info {

int ShowImage(const std::string& path) {
  Expected<image::ImageLayers> read = image::ReadExr(path);
  if (!read.ok()) {
    std::fprintf(stderr, "raystack-info: %s\n", read.status().message().c_str());
    return 1;
  }
  const image::ImageLayers& im = *read;
  const char* state = im.provenance.empty() ? "unknown (not written by raystack render)"
                      : im.partial          ? "partial"
                                            : "complete";
  std::printf("image            %s\n", path.c_str());
  std::printf("size             %d x %d\n", im.width, im.height);
  std::printf("state            %s\n", state);
  if (!im.stopped.empty()) std::printf("stopped          %s\n", im.stopped.c_str());
  if (!im.samples.empty()) {
    const auto [fewest, most] = std::minmax_element(im.samples.begin(), im.samples.end());
    double sum = 0;
    size_t none = 0;
    for (const uint32_t n : im.samples) sum += n, none += n == 0;
    std::printf("samples/pixel    %u to %u, mean %.2f (%zu pixels without a sample)\n", *fewest,
                *most, sum / static_cast<double>(im.samples.size()), none);
  }
  // The provenance's lines under one another (scene, camera, lights, settings, build).
  const char* label = "provenance       ";
  size_t begin = 0;
  while (begin < im.provenance.size()) {
    size_t end = im.provenance.find('\n', begin);
    if (end == std::string::npos) end = im.provenance.size();
    if (end > begin)
      std::printf("%s%.*s\n", label, static_cast<int>(end - begin), im.provenance.c_str() + begin);
    label = "                 ";
    begin = end + 1;
  }
  if (im.provenance.empty()) {
    std::fprintf(stderr, "raystack-info: %s: no raystack.state: not a frame raystack render wrote\n",
                 path.c_str());
    return 1;
  }
  if (im.partial) {
    std::fprintf(stderr, "raystack-info: %s: a partial frame (a checkpoint, or what a stopped or "
                 "failed job kept): raystack render --resume continues it\n", path.c_str());
    return 1;
  }
  return 0;
}

}  // namespace raystack::info
