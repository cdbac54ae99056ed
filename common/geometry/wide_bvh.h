#pragma once
// A wide BVH over a whole triangle mesh in memory, for models that fit in RAM: one tree
// instead of the store's octree of blocks, each with its own binary BVH. The binned-SAH binary
// tree (BuildBvh) is collapsed into nodes of 8 children (near the leaves by the SAH-optimal
// WideCollapse) whose boxes are tested 8 at a time (AVX2; 4 at a time with SSE2), and each
// leaf holds its (at most 4) triangles' vertices in place, laid out lane by lane, so a leaf
// costs no index or vertex gathers. Measured on the dragon (embree_bench, one thread): 8
// children rather than 4 gave +9% primary and +4% random rays/s.
//
// Hits are bit-identical to the block traversals: the leaves run IntersectTriangle's float edge
// test 4 triangles at a time with the same operations lane by lane, then IntersectTriangle
// itself on the triangles that pass, and the closest hit follows CloserThan. Box tests follow
// IntersectBox's expressions and slack, with boxes widened by a margin that covers the float
// triangle test's tolerance (see BoxRay), so no box holding the closest hit is culled.
//
// Building allocates; queries never do and may run on several threads at once.

#include <cstdint>
#include <span>
#include <vector>

#include "common/base/huge_page_allocator.h"
#include "common/geometry/ray.h"
#include "common/geometry/vec.h"

namespace raystack {

// Where a triangle came from (e.g. its block and index there), reported in its hits.
struct TriangleOrigin {
  uint32_t block, local;
};

class WideBvh {
 public:
  static constexpr int kWidth = 8;  // children per node
  // Leaves are numbered in 29 bits of a child reference, and a leaf holds at least one triangle:
  // at most this many triangles (RenderEngine refuses --mode bvh for a larger store).
  static constexpr uint64_t kMaxTriangles = uint64_t{1} << 29;

  WideBvh() = default;
  // Triangle i has corners vertices[3i .. 3i+2], source id ids[i] (the tie-breaker of
  // CloserThan) and origin origins[i]. Every vertex must be finite. The binary tree is built
  // on `threads` threads (BvhBuildOptions::threads); the tree does not depend on it.
  WideBvh(std::span<const Vec3f> vertices, std::span<const uint32_t> ids,
          std::span<const TriangleOrigin> origins, int threads = 1);

  // The walks are in wide_bvh_walks.cpp.
  // Closest hit in (ray.tmin, hit->t], ties broken by CloserThan, as BlockView::Intersect.
  // On a closer hit, fills t, u, v, triangle_id, and block_id and local_triangle from the
  // triangle's origin, and returns true.
  bool Intersect(const Ray& ray, Hit* hit) const;
  // Any hit in (ray.tmin, ray.tmax).
  bool Occluded(const Ray& ray) const;

  // Packets: up to kPacketSize rays walked together, each node's and leaf's loads and tests
  // shared by the rays that reach it, with the rays in SIMD lanes. Coherent rays (neighbouring
  // pixels' primary rays, their shadow rays towards one light) walk mostly the same nodes.
  // Lane by lane, the tests are the single-ray ones, so results are the same bit for bit.
  // Rays whose direction signs or dominant axis differ from the others', or that point or start
  // far from them, are walked as further packets (one alone takes the single-ray walk), so
  // incoherent rays cost about what they cost alone.
  // 16 rays (4 x 4 pixels) walk as one packet where the CPU has AVX2; elsewhere (SSE2) each
  // run of 8 walks as its own, where 16 do not pay (see wide_bvh_packet_walk.inc).
  static constexpr int kPacketSize = 16;
  // As Intersect(rays[i], &hits[i]) for every i < rays.size() <= kPacketSize; bit i of the
  // result is set when hits[i] was replaced by a closer hit.
  uint32_t IntersectPacket(std::span<const Ray> rays, std::span<Hit> hits) const;
  // Bit i set when Occluded(rays[i]).
  uint32_t OccludedPacket(std::span<const Ray> rays) const;
  // Single rays and packets take the widest copy of their walks the CPU has (the same results,
  // faster; wide_bvh_walks.cpp): the build's baseline (SSE2 on x86-64), AVX2, or the AVX2 code
  // with AVX-512's instructions allowed. Narrowest first.
  enum class WalkIsa { kBaseline, kAvx2, kAvx512 };
  // For tests and benchmarks: walks take the widest copy up to `widest` (kAvx512: no limit).
  // Returns the copy now used.
  static WalkIsa LimitWalks(WalkIsa widest);
  static const char* WalkIsaName(WalkIsa isa);

  size_t triangle_count() const { return triangle_count_; }
  size_t node_count() const { return nodes_.size(); }
  size_t bytes() const;

 private:
  // kWidth children: their boxes as [lower x, y, z, upper x, y, z][child], and their references:
  // an inner node's index, or kLeaf | (leaf group << 2) | (triangles - 1), or kEmpty (whose
  // box is empty).
  struct alignas(64) Node {
    float box[6][kWidth];
    uint32_t child[kWidth];
    // Bit k set when child k is not kEmpty. Traversals never enter the others: an empty box
    // culls every finite ray, but a ray with a NaN or infinite component (or pads that overflow
    // on an extreme model) can turn all three of its slab tests into NaNs, which the box test
    // ignores, and would then walk into a child that is not there. (In the 32 bytes a node
    // left unused.)
    uint32_t occupied;
  };
  static_assert(sizeof(Node) == 256);
  // Up to 4 triangles: corner c's coordinate a of triangle k is p[c][a][k]. Unused lanes repeat
  // the last triangle and are masked out by the count in the reference. The origins live in the
  // leaf rather than in a table of their own: 192 bytes are 3 whole cache lines, as many as the
  // 160 bytes without them spanned, and a hit's origin costs no further miss (the dragon's
  // random rays: 1.67-1.79 -> 2.21-2.27 M rays/s, embree_bench, one thread).
  struct alignas(64) Leaf {
    float p[3][3][4];
    uint32_t id[4];
    TriangleOrigin origin[4];
  };
  static_assert(sizeof(Leaf) == 192);
  static constexpr uint32_t kLeaf = 0x80000000u;
  static constexpr uint32_t kEmpty = 0xffffffffu;

  template <typename NodeHitsFn, typename LeafFn>
  void Traverse(NodeHitsFn&& node_hits, const float* tmax, LeafFn&& leaf) const;
  // Requests the cache lines of the children in `mask`.
  void Prefetch(const uint32_t child[kWidth], uint32_t mask) const;

  // On huge pages where the kernel has them (see HugePageAllocator): the walks reach nodes and
  // leaves all over both arrays (dragon, one thread: random rays +5%).
  std::vector<Node, HugePageAllocator<Node>> nodes_;  // the root is nodes_[0]
  std::vector<Leaf, HugePageAllocator<Leaf>> leaves_;
  size_t triangle_count_ = 0;
  float magnitude_ = 0;  // the largest |coordinate| of any vertex: sets the boxes' margin
  float extent_ = 0;     // the model box's largest side: sets how far apart a packet's rays may start

  friend class WideBvhBuilder;
  friend class WideBvhWalks;  // the single-ray and packet walks (wide_bvh_walks.cpp)
};

}  // namespace raystack
