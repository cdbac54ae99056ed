// libFuzzer target: the block decoder (lz4 + byte shuffle) and the block parser, then rays
// through whatever parsed, single and batched, so a hostile block that passes Parse() is
// traversed too. Input: a 5-byte prefix, then the block.
//   bytes 0-3  raw size the index claims (little-endian; capped so a huge claim is cheap)
//   byte 4     bit 0: the rest is a raw block, parsed as is; else a stored block, decoded
//              first; bit 1: the stored block is shuffled
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <vector>

#include "common/base/check.h"
#include "common/store/block_codec.h"
#include "common/store/block_view.h"
#include "tests/fuzz/fuzz_quiet.h"

namespace {

using raystack::Hit;
using raystack::Ray;
using raystack::Vec3f;

void TraceThrough(const raystack::store::BlockView& view) {
  const raystack::Bounds3f cell = view.cell();
  const Vec3f center = cell.Center();
  std::vector<Ray> rays;
  const Vec3f origins[] = {cell.lower, cell.upper, {cell.lower.x, cell.upper.y, cell.lower.z},
                           center + Vec3f{0, 0, 1e3f}};
  for (const Vec3f& o : origins) {
    rays.push_back({o, center - o});
    rays.push_back({o, {1, 0, 0}});  // axis-parallel: infinite inverse directions
  }
  std::vector<Hit> hits(rays.size());
  std::vector<uint8_t> occluded(rays.size());
  for (size_t i = 0; i < rays.size(); ++i) {
    Hit hit;
    if (view.Intersect(rays[i], &hit)) {
      CHECK(hit.local_triangle < view.triangle_count());
      (void)view.Material(hit.local_triangle);
      if (view.has_normals()) {
        for (int c = 0; c < 3; ++c) (void)view.Normal(view.VertexIndex(hit.local_triangle, c));
      }
    }
    (void)view.Occluded(rays[i]);
  }
  view.IntersectBatch(rays, hits);
  view.OccludedBatch(rays, occluded);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace raystack::store;
  if (size < 5) return 0;
  uint32_t raw_bytes;
  std::memcpy(&raw_bytes, data, 4);
  raw_bytes %= 1u << 20;
  const uint8_t mode = data[4];
  const std::span<const uint8_t> body(data + 5, size - 5);

  AlignedBuffer raw;
  uint64_t raw_size = 0;
  if (mode & 1) {
    raw.Reserve(body.size() + 16);
    if (!body.empty()) std::memcpy(raw.data(), body.data(), body.size());
    raw_size = body.size();
  } else {
    AlignedBuffer scratch;
    if (!DecodeBlock(body, raw_bytes, (mode & 2) != 0, &scratch, &raw).ok()) return 0;
    raw_size = raw_bytes;
  }
  raystack::Expected<BlockView> view = BlockView::Parse(raw.data(), raw_size, 7);
  if (view.ok()) TraceThrough(*view);
  return 0;
}
