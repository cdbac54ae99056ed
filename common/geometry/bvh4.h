#pragma once
// A 4-wide BVH over a whole triangle mesh in memory, for models that fit in RAM: one tree
// instead of the store's octree of blocks, each with its own binary BVH. The binned-SAH binary
// tree (BuildBvh) is collapsed into nodes of 4 children whose boxes are tested at once (SSE2),
// and each leaf holds its (at most 4) triangles' vertices in place, laid out lane by lane, so
// a leaf costs no index or vertex gathers.
//
// Hits are bit-identical to the block traversals: the leaves run IntersectTriangle's float edge
// test 4 triangles at a time with the same operations lane by lane, then IntersectTriangle
// itself on the triangles that pass, and the closest hit follows CloserThan. Box tests follow
// IntersectBox's expressions and slack, so no box holding the closest hit is culled.
//
// Building allocates; queries never do and may run on several threads at once.

#include <cstdint>
#include <span>
#include <vector>

#include "common/geometry/ray.h"
#include "common/geometry/triangle.h"
#include "common/geometry/vec.h"

namespace raystack {

class Bvh4 {
 public:
  Bvh4() = default;
  // Triangle i has corners vertices[3i .. 3i+2] and source id ids[i] (the tie-breaker of
  // CloserThan). Every vertex must be finite.
  Bvh4(std::span<const Vec3f> vertices, std::span<const uint32_t> ids);

  // Closest hit in (ray.tmin, hit->t], ties broken by CloserThan, as BlockView::Intersect.
  // On a closer hit, fills t, u, v and triangle_id, sets local_triangle to the triangle's
  // index in the constructor's input (block_id is left as it was) and returns true.
  bool Intersect(const Ray& ray, Hit* hit) const;
  // Any hit in (ray.tmin, ray.tmax).
  bool Occluded(const Ray& ray) const;

  size_t triangle_count() const { return triangle_count_; }
  size_t node_count() const { return nodes_.size(); }
  size_t bytes() const;

 private:
  // 4 children: their boxes as [lower x, y, z, upper x, y, z][child], and their references:
  // an inner node's index, or kLeaf | (leaf group << 2) | (triangles - 1), or kEmpty (whose
  // box is empty, so no ray meets it).
  struct alignas(64) Node {
    float box[6][4];
    uint32_t child[4];
  };
  // Up to 4 triangles: corner c's coordinate a of triangle k is p[c][a][k]. Unused lanes repeat
  // the last triangle and are masked out by the count in the reference.
  struct alignas(16) Leaf {
    float p[3][3][4];
    uint32_t id[4];
  };
  static constexpr uint32_t kLeaf = 0x80000000u;
  static constexpr uint32_t kEmpty = 0xffffffffu;

  // Bit k set: triangle k of `leaf` (k < n) passes the float edge test.
  void Prefetch(const uint32_t child[4], uint32_t mask) const;
  static uint32_t EdgeCandidates(const RayTriangleSetup& s, const Leaf& leaf, uint32_t n);

  std::vector<Node> nodes_;  // the root is nodes_[0]
  std::vector<Leaf> leaves_;
  std::vector<uint32_t> input_index_;  // per leaf lane: the triangle's index in the input
  size_t triangle_count_ = 0;

  friend class Bvh4Builder;
};

}  // namespace raystack
