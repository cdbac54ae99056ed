#pragma once
// Where each section of a raw block lives. Sections follow the BlockHeader in this order, each
// starting on a 16-byte boundary so a decoded block is used in place (BvhNode, float arrays):
//   nodes        BvhNode[node_count]
//   positions    float x[V], y[V], z[V]             (SoA: similar bytes sit together for lz4)
//   indices      u16 or u32 [3 * T]                 (kBlockIndices32)
//   triangle_ids u32[T]                             (source triangle ids)
//   materials    u16[T]                             (only with kBlockPerTriangleMaterial)
//   normals      float x[V], y[V], z[V]             (only with kBlockNormals)
//   uvs          float u[V], v[V]                   (only with kBlockUvs)

#include <cstddef>
#include <cstdint>

#include "common/store/format.h"

namespace raystack::store {

struct BlockLayout {
  uint64_t nodes = 0, positions = 0, indices = 0, triangle_ids = 0, materials = 0, normals = 0,
           uvs = 0;
  uint64_t total = 0;  // raw block size in bytes

  // Offsets for a header's counts and flags. Computed in 64 bits: a hostile header cannot
  // overflow it (the caller compares `total` with the real size).
  static BlockLayout For(const BlockHeader& header);
};

inline constexpr uint64_t AlignUp16(uint64_t n) { return (n + 15) & ~uint64_t{15}; }

inline BlockLayout BlockLayout::For(const BlockHeader& h) {
  const uint64_t v = h.vertex_count, t = h.triangle_count;
  BlockLayout l;
  uint64_t at = sizeof(BlockHeader);
  l.nodes = at;
  at = AlignUp16(at + uint64_t{h.node_count} * 32);
  l.positions = at;
  at = AlignUp16(at + v * 12);
  l.indices = at;
  at = AlignUp16(at + t * 3 * ((h.flags & kBlockIndices32) ? 4 : 2));
  l.triangle_ids = at;
  at = AlignUp16(at + t * 4);
  l.materials = at;
  if (h.flags & kBlockPerTriangleMaterial) at = AlignUp16(at + t * 2);
  l.normals = at;
  if (h.flags & kBlockNormals) at = AlignUp16(at + v * 12);
  l.uvs = at;
  if (h.flags & kBlockUvs) at = AlignUp16(at + v * 8);
  l.total = at;
  return l;
}

}  // namespace raystack::store
