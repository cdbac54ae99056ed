#include "tools/info/image_info.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "common/image/exr_io.h"

namespace raystack::info {

namespace {

// Each layer's range and mean, and its values that are not finite: what a researcher checked
// with a reader of his own (nothing here read the pixels).
void PrintLayers(const image::ImageLayers& im) {
  const size_t n = im.pixel_count();
  auto channel = [&](const char* name, const std::vector<float>& values, size_t stride, size_t c) {
    if (values.size() < n * stride) return;
    double sum = 0, lo = std::numeric_limits<double>::infinity(), hi = -lo;
    size_t finite = 0, infinite = 0, nan = 0;
    for (size_t i = 0; i < n; ++i) {
      const double v = values[i * stride + c];
      if (std::isnan(v)) ++nan;
      else if (std::isinf(v)) ++infinite;
      else ++finite, sum += v, lo = std::min(lo, v), hi = std::max(hi, v);
    }
    std::printf("layer %-10s ", name);
    if (finite > 0) std::printf("%.6g to %.6g, mean %.6g", lo, hi, sum / static_cast<double>(finite));
    if (infinite > 0) std::printf("%s%zu infinite", finite > 0 ? "; " : "", infinite);
    if (nan > 0) std::printf("%s%zu NaN", finite + infinite > 0 ? "; " : "", nan);
    std::printf("\n");
  };
  const char* rgba[] = {"R", "G", "B", "A"};
  for (size_t c = 0; c < 4; ++c) channel(rgba[c], im.rgba, 4, c);
  channel("Z", im.z, 1, 0);  // (infinite: the misses)
  const char* normal[] = {"N.x", "N.y", "N.z"};
  for (size_t c = 0; c < 3; ++c) channel(normal[c], im.normal, 3, c);
  const char* albedo[] = {"albedo.r", "albedo.g", "albedo.b"};
  for (size_t c = 0; c < 3; ++c) channel(albedo[c], im.albedo, 3, c);
  channel("variance", im.variance, 1, 0);
}

}  // namespace

bool LooksLikeExr(const std::string& path) {
  unsigned char magic[4] = {};
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) return false;
  const size_t n = std::fread(magic, 1, sizeof magic, f);
  std::fclose(f);
  return n == sizeof magic && magic[0] == 0x76 && magic[1] == 0x2f && magic[2] == 0x31 &&
         magic[3] == 0x01;
}

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
  PrintLayers(im);
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
