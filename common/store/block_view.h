#pragma once
// A decoded block, read in place: a view over the raw bytes (which the caller owns and keeps
// alive and 16-byte aligned). Parse() validates every count, offset, index and the BVH's shape,
// so a block whose checksum is right but whose content is hostile still cannot make a
// traversal read out of bounds or loop. Intersection never allocates.

#include <bit>
#include <cstdint>
#include <cstring>
#include <limits>
#include <span>

#include "common/base/status.h"
#include "common/geometry/bounds.h"
#include "common/geometry/bvh.h"
#include "common/geometry/next_float.h"
#include "common/geometry/ray.h"
#include "common/geometry/triangle.h"
#include "common/store/format.h"
#include "common/store/octree.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace raystack::store {

class BlockView {
 public:
  BlockView() = default;

  // Checks `raw` (size bytes) as the raw form of block `block_id` (the id names it in errors
  // and hits).
  static Expected<BlockView> Parse(const uint8_t* raw, uint64_t size, uint32_t block_id);

  const BlockHeader& header() const { return *header_; }
  uint32_t id() const { return id_; }
  uint32_t triangle_count() const { return header_->triangle_count; }
  uint32_t vertex_count() const { return header_->vertex_count; }
  Bounds3f cell() const;
  std::span<const BvhNode> nodes() const { return {nodes_, header_->node_count}; }
  // Its BVH root's box (empty without triangles): what the index repeats as the block's bounds.
  BoxBounds bounds() const;

  Vec3f Vertex(uint32_t i) const { return {x_[i], y_[i], z_[i]}; }
  void TriangleVertices(uint32_t t, Vec3f* p0, Vec3f* p1, Vec3f* p2) const;
  uint32_t VertexIndex(uint32_t t, int corner) const;
  uint32_t TriangleId(uint32_t t) const { return ids_[t]; }
  // The largest triangle id (0 without triangles), and the box of every vertex (empty without):
  // for the reader's checks of what a block claims (StoreReader::Decode).
  uint32_t LargestTriangleId() const;
  Bounds3f VertexBounds() const;
  // Material index into the store's material table, or kNoMaterial.
  uint32_t Material(uint32_t t) const;
  bool has_normals() const { return header_->flags & kBlockNormals; }
  bool has_uvs() const { return header_->flags & kBlockUvs; }
  Vec3f Normal(uint32_t vertex) const { return {nx_[vertex], ny_[vertex], nz_[vertex]}; }

  // Closest hit in (ray.tmin, hit->t], ties broken by CloserThan. Updates `hit` (with this
  // block's id) and returns true when it found a closer one.
  bool Intersect(const Ray& ray, Hit* hit) const;
  // Any hit in (ray.tmin, ray.tmax).
  bool Occluded(const Ray& ray) const;

  // Asks the CPU to bring the whole block into its caches, without waiting. A batch's walk
  // goes from node to node, each load waiting for the last; a block resident but not touched
  // lately is in none of the caches, so every step missed. The prefetches are all in flight at
  // once (see slave/ray_thread.cpp for what it gained). Blocks are ~32 KB (raystack-prep's
  // --max-block-kb caps them at 128 KB by default); past kMaxPrefetchBytes, a bound rather than
  // a tuned figure, a batch meets a small part of a block and would find its lines pushed out.
  static constexpr uint64_t kMaxPrefetchBytes = 256 << 10;
  void Prefetch() const {
    const auto* p = reinterpret_cast<const char*>(header_);
    const uint64_t end = bytes_ < kMaxPrefetchBytes ? bytes_ : kMaxPrefetchBytes;
    for (uint64_t offset = 0; offset < end; offset += 64) __builtin_prefetch(p + offset, 0, 3);
  }

  // The same queries for a batch of rays (a block's waiting queue): results equal, bit for
  // bit, n calls of the single-ray forms. Rays are grouped by direction octant and traced
  // as packets of 4 (SSE2) within each group, so coherent queues gain most; any order, size
  // and alignment of the spans is fine (the spans must have equal sizes).
  void IntersectBatch(std::span<const Ray> rays, std::span<Hit> hits) const;
  void OccludedBatch(std::span<const Ray> rays, std::span<uint8_t> occluded) const;

 private:
  // Which of triangles [first, first + n) (n <= 4) may be hit: IntersectTriangle's float edge
  // test for 4 triangles at once (SSE2). Every triangle it drops IntersectTriangle rejects too
  // (the same float operations; a zero edge value, for which IntersectTriangle decides in
  // double, is never dropped), so the leaves test only the rest, in order, with the same results.
  uint32_t EdgeCandidates(const RayTriangleSetup& setup, uint32_t first, uint32_t n) const;
  // Calls test(i, p0, p1, p2) for each triangle of [first, first + count) EdgeCandidates keeps,
  // in order, until it returns true; returns whether it did.
  template <typename Test>
  bool ForEachCandidate(const RayTriangleSetup& setup, uint32_t first, uint32_t count,
                        Test&& test) const;
  // Tests triangles [first, first + count) for one ray: the shared body of the single-ray
  // and packet traversals, so both make the same operations in the same order.
  bool IntersectLeaf(const RayTriangleSetup& setup, const Ray& ray, uint32_t first,
                     uint32_t count, float* tmax, Hit* hit) const;
  bool OccludedLeaf(const RayTriangleSetup& setup, const Ray& ray, uint32_t first,
                    uint32_t count) const;

  uint32_t id_ = 0;
  const BlockHeader* header_ = nullptr;
  uint64_t bytes_ = 0;  // the raw block's size, from header_
  const BvhNode* nodes_ = nullptr;
  const float *x_ = nullptr, *y_ = nullptr, *z_ = nullptr;
  const uint16_t* indices16_ = nullptr;
  const uint32_t* indices32_ = nullptr;
  const uint32_t* ids_ = nullptr;
  const uint16_t* materials_ = nullptr;
  float magnitude_ = 0;  // the largest |coordinate| of its vertices: the box tests' margin
  const float *nx_ = nullptr, *ny_ = nullptr, *nz_ = nullptr;
};


inline uint32_t BlockView::EdgeCandidates(const RayTriangleSetup& s, uint32_t first,
                                          uint32_t n) const {
#if defined(__SSE2__)
  // Lanes past n repeat the last triangle (masked out below). Each lane vector is built in
  // registers from scalar loads: filling a stack array lane by lane and loading it as one
  // vector stalls on store forwarding (4 narrow stores feeding a wide load), 9 times a call.
  uint32_t vi[3][4];
  for (uint32_t k = 0; k < 4; ++k) {
    const uint32_t t = first + (k < n ? k : n - 1);
    for (int c = 0; c < 3; ++c) vi[c][k] = VertexIndex(t, c);
  }
  const float* const axis_data[3] = {x_, y_, z_};
  // IntersectTriangle's float expressions, lane by lane: p - origin, then the shear.
  __m128 x[3], y[3];
  for (int c = 0; c < 3; ++c) {
    __m128 d[3];
    for (int a = 0; a < 3; ++a) {
      const float* q = axis_data[a];
      d[a] = _mm_sub_ps(_mm_setr_ps(q[vi[c][0]], q[vi[c][1]], q[vi[c][2]], q[vi[c][3]]),
                        _mm_set1_ps(s.origin[a]));
    }
    x[c] = _mm_sub_ps(d[s.kx], _mm_mul_ps(_mm_set1_ps(s.sx), d[s.kz]));
    y[c] = _mm_sub_ps(d[s.ky], _mm_mul_ps(_mm_set1_ps(s.sy), d[s.kz]));
  }
  return ~EdgeRejected4(x, y) & ((1u << n) - 1);
#else
  (void)s;
  (void)first;
  return (1u << n) - 1;
#endif
}

template <typename Test>
bool BlockView::ForEachCandidate(const RayTriangleSetup& setup, uint32_t first, uint32_t count,
                                 Test&& test) const {
  for (uint32_t group = first; group < first + count; group += 4) {
    const uint32_t n = first + count - group < 4 ? first + count - group : 4;
    for (uint32_t keep = EdgeCandidates(setup, group, n); keep; keep &= keep - 1) {
      const uint32_t i = group + static_cast<uint32_t>(std::countr_zero(keep));
      Vec3f p0, p1, p2;
      TriangleVertices(i, &p0, &p1, &p2);
      if (test(i, p0, p1, p2)) return true;
    }
  }
  return false;
}

inline bool BlockView::IntersectLeaf(const RayTriangleSetup& setup, const Ray& ray,
                                     uint32_t first, uint32_t count, float* tmax,
                                     Hit* hit) const {
  bool found = false;
  ForEachCandidate(setup, first, count, [&](uint32_t i, Vec3f p0, Vec3f p1, Vec3f p2) {
    float t, u, w;
    if (IntersectTriangle(setup, p0, p1, p2, ray.tmin, *tmax, &t, &u, &w) &&
        CloserThan(t, ids_[i], *hit)) {
      hit->t = t;
      hit->u = u;
      hit->v = w;
      hit->triangle_id = ids_[i];
      hit->local_triangle = i;
      hit->block_id = id_;
      *tmax = NextUp(t);
      found = true;
    }
    return false;  // every candidate: a later one may be closer
  });
  return found;
}

inline bool BlockView::OccludedLeaf(const RayTriangleSetup& setup, const Ray& ray,
                                    uint32_t first, uint32_t count) const {
  return ForEachCandidate(setup, first, count, [&](uint32_t, Vec3f p0, Vec3f p1, Vec3f p2) {
    float t, u, w;
    return IntersectTriangle(setup, p0, p1, p2, ray.tmin, ray.tmax, &t, &u, &w);
  });
}

inline uint32_t BlockView::VertexIndex(uint32_t t, int corner) const {
  const uint32_t k = 3 * t + static_cast<uint32_t>(corner);
  return indices32_ ? indices32_[k] : indices16_[k];
}

inline void BlockView::TriangleVertices(uint32_t t, Vec3f* p0, Vec3f* p1, Vec3f* p2) const {
  *p0 = Vertex(VertexIndex(t, 0));
  *p1 = Vertex(VertexIndex(t, 1));
  *p2 = Vertex(VertexIndex(t, 2));
}

inline uint32_t BlockView::Material(uint32_t t) const {
  if (!materials_) return header_->constant_material;
  return materials_[t] == kNoMaterial16 ? kNoMaterial : materials_[t];
}

}  // namespace raystack::store
