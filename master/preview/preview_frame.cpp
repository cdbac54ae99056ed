#include "master/preview/preview_frame.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

namespace raystack::master::preview {

FilmSnapshot TakeSnapshot(const render::Film& film, uint32_t frame,
                          std::chrono::steady_clock::duration* held) {
  FilmSnapshot s;
  s.width = film.width();
  s.height = film.height();
  s.frame = frame;
  film.ResolveColour(&s.rgb, &s.counts, held);
  for (uint32_t n : s.counts) s.samples_merged += n;
  return s;
}

void EncodeFrame(const FilmSnapshot& snapshot, float exposure, const Srgb8Encoder& encoder,
                 std::vector<uint8_t>* out) {
  const size_t pixels = static_cast<size_t>(snapshot.width) * static_cast<size_t>(snapshot.height);
  out->resize(kFrameHeaderBytes + 4 * pixels);
  const FrameHeader header{kFrameMagic, kFrameVersion, static_cast<uint32_t>(snapshot.width),
                           static_cast<uint32_t>(snapshot.height), snapshot.frame, exposure,
                           snapshot.samples_merged};
  std::memcpy(out->data(), &header, sizeof header);  // x86-64 and the page: little-endian
  const float scale = std::exp2(exposure);
  uint8_t* p = out->data() + kFrameHeaderBytes;
  for (size_t i = 0; i < pixels; ++i, p += 4) {
    const bool computed = snapshot.counts[i] > 0;
    for (size_t c = 0; c < 3; ++c) p[c] = computed ? encoder.Encode(snapshot.rgb[3 * i + c] * scale) : 0;
    p[3] = computed ? 255 : 0;
  }
}

}  // namespace raystack::master::preview
