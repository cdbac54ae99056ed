#pragma once
// The image half of the preview stream: a copy of the film taken off the render's path, and
// its encoding as one binary WebSocket message (tone-mapped RGBA8 with "computed" in alpha),
// tone-mapped exactly as the PNG quick look (image::LinearToSrgb8) so the page and the PNG
// agree to the bit.

#include <array>
#include <chrono>
#include <cstdint>
#include <vector>

#include "common/image/srgb8.h"
#include "common/render/film.h"

namespace raystack::master::preview {

// The film as the preview needs it. Plain data, owned by whoever took it.
struct FilmSnapshot {
  int width = 0, height = 0;
  uint32_t frame = 0;
  uint64_t samples_merged = 0;
  std::vector<float> rgb;        // mean radiance, 3 per pixel, row 0 at the top
  std::vector<uint32_t> counts;  // samples per pixel; 0 = not computed yet
};

// Copies `film` (thread-safe, as Film::Resolve); `held` as in Film::ResolveColour.
FilmSnapshot TakeSnapshot(const render::Film& film, uint32_t frame,
                          std::chrono::steady_clock::duration* held = nullptr);

// Binary frame message: a 32-byte little-endian header, then width*height RGBA8 pixels.
inline constexpr uint32_t kFrameMagic = 0x56505352;  // "RSPV"
inline constexpr uint32_t kFrameVersion = 1;
inline constexpr size_t kFrameHeaderBytes = 32;
// Larger frames are not streamed (the message would exceed the bound every viewer accepts).
inline constexpr uint64_t kMaxFramePixels = uint64_t{4096} * 4096;
inline bool Streamed(int width, int height) {
  return static_cast<uint64_t>(width) * static_cast<uint64_t>(height) <= kMaxFramePixels;
}

struct FrameHeader {
  uint32_t magic, version, width, height, frame;
  float exposure;
  uint64_t samples_merged;
};
static_assert(sizeof(FrameHeader) == kFrameHeaderBytes);

using image::Srgb8Encoder;  // (common/image/srgb8.h) the page's tone map is the PNG's

// Writes the message of `snapshot` at `exposure` (EV) into `out` (resized; its capacity is
// reused from frame to frame). Alpha is 255 for pixels with a sample and 0 for the rest, which
// the page fills from their quadtree ancestors.
void EncodeFrame(const FilmSnapshot& snapshot, float exposure, const Srgb8Encoder& encoder,
                 std::vector<uint8_t>* out);

}  // namespace raystack::master::preview
