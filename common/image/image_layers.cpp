#include "common/image/image_layers.h"

#include <limits>

#include "common/base/check.h"
#include "common/base/populate.h"

namespace raystack::image {

namespace {

// `v` as n copies of `value`. New memory is mapped in one call before it is written
// (PopulateForWrite): written a page at a time, the master's resolved 960x540 frame (27 MB)
// took ~6,600 page faults between two frames, each a guest exit on a PVM VM (~12 us), while
// the slaves waited for the next frame's first tiles.
template <typename T>
void Fill(std::vector<T>* v, size_t n, T value) {
  if (v->capacity() < n) {
    std::vector<T>().swap(*v);  // nothing to copy into the new memory
    v->reserve(n);
    PopulateForWrite(v->data(), n * sizeof(T));
  }
  v->assign(n, value);
}

}  // namespace

void ImageLayers::Resize(int w, int h) {
  CHECK(w >= 0 && h >= 0);
  width = w;
  height = h;
  const size_t n = pixel_count();
  // assign, not resize: every layer starts from its fill value, whatever it held before.
  Fill(&rgba, 4 * n, 0.0f);
  Fill(&z, n, std::numeric_limits<float>::infinity());
  Fill(&normal, 3 * n, 0.0f);
  Fill(&albedo, 3 * n, 0.0f);
  Fill(&samples, n, 0u);
  Fill(&variance, n, 0.0f);
}

}  // namespace raystack::image
