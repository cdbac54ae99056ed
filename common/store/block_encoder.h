#pragma once
// Builds the raw form of one block from the triangles the converter assigned to a leaf cell:
// deduplicates vertices, builds the block's BVH over the triangles' bounds clipped to the cell,
// orders triangles as the BVH leaves want them, and lays out only the sections the triangles
// need (no normals, uvs or material ids where they have none).

#include <cstdint>
#include <span>
#include <vector>

#include "common/geometry/bounds.h"
#include "common/geometry/bvh.h"
#include "common/store/format.h"

namespace raystack::store {

// A triangle as the converter carries it (44 bytes, no padding). Material ids use 24 bits; the
// two top bits say whether optional attributes follow it.
struct PackedTriangle {
  Vec3f p[3];
  uint32_t id;                  // source triangle id
  uint32_t material_and_flags;  // kNoMaterial or an index; | kHasNormals | kHasUvs

  static constexpr uint32_t kHasNormals = 1u << 31;
  static constexpr uint32_t kHasUvs = 1u << 30;
  uint32_t material() const { return material_and_flags & 0x00ffffffu; }
  bool has_normals() const { return material_and_flags & kHasNormals; }
  bool has_uvs() const { return material_and_flags & kHasUvs; }
};
static_assert(sizeof(PackedTriangle) == 44);

struct TriangleAttributes {
  Vec3f n[3];
  float uv[3][2];
};
static_assert(sizeof(TriangleAttributes) == 60);

struct EncodeInput {
  std::span<const PackedTriangle> triangles;
  // Parallel to `triangles` when any of them has attributes, else empty.
  std::span<const TriangleAttributes> attributes;
  std::span<const uint32_t> refs;          // indices into `triangles`: this block's triangles
  std::span<const Bounds3f> ref_bounds;    // their bounds clipped to the cell (parallel to refs)
  Bounds3f cell;
};

// Reusable scratch for one encoding thread, so encoding allocates only while buffers grow.
class BlockEncoder {
 public:
  explicit BlockEncoder(BvhBuildOptions bvh = {}) : bvh_(bvh) {}

  // Writes the raw block into `raw` (resized). Returns its vertex count.
  uint32_t Encode(const EncodeInput& input, std::vector<uint8_t>* raw);
  // The last encoded block's bounds: its BVH root node's box (empty without triangles), which
  // the index repeats (BlockEntry::bounds_lower/upper).
  const Bounds3f& bounds() const { return bounds_; }

 private:
  uint32_t VertexOf(const EncodeInput& in, uint32_t tri, int corner, bool attributes);

  BvhBuildOptions bvh_;
  Bounds3f bounds_;
  std::vector<BvhBuildPrimitive> prims_;
  std::vector<uint32_t> order_;
  std::vector<uint32_t> slots_;  // open-addressing vertex table: vertex index + 1, 0 = free
  // Per vertex: tri * 3 + corner it came from, in 64 bits: `tri` indexes the converter's whole
  // bucket, which may hold more than 2^32 / 3 triangles under a large --mem-limit.
  std::vector<uint64_t> vertex_source_;
  std::vector<uint32_t> corners_;        // per (triangle in BVH order, corner): vertex index
};

}  // namespace raystack::store
