#pragma once
// The level-1 octree (the "management level", always in RAM): which cells exist, which are
// empty, and which blocks fill each leaf. It answers two questions for a ray: which leaves it
// crosses, front to back, and where each starts and ends along the ray.

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>

#include "common/geometry/bounds.h"
#include "common/geometry/bvh.h"
#include "common/geometry/next_float.h"
#include "common/geometry/ray.h"
#include "common/store/format.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace raystack::store {

// A box as plain floats (no member initialisers, so arrays of them cost nothing to declare).
// An empty box has lower = +inf and upper = -inf: no ray meets it.
struct BoxBounds {
  float lower[3], upper[3];
};

// Whether a ray may meet anything inside `box` before its best hit so far `t_best` (or the end
// of a shadow ray): exactly the test a block's BVH makes of its root box, IntersectBox over
// [tmin, NextUp(t_best)] (BlockView::Intersect's interval). When it fails for a block's
// bounds the block cannot change the ray's result, so walks skip it; when it fails for the
// union of a node's blocks' bounds, for every block below the node.
inline bool MayHit(const RayBoxSetup& s, const BoxBounds& box, float tmin, float t_best) {
  float t_enter;
  return IntersectBox(s, box.lower, box.upper, tmin, NextUp(t_best), &t_enter);
}

inline BoxBounds BoundsOf(const BlockEntry& e) {
  return {{e.bounds_lower[0], e.bounds_lower[1], e.bounds_lower[2]},
          {e.bounds_upper[0], e.bounds_upper[1], e.bounds_upper[2]}};
}

// Per octree node, the union of its blocks' bounds, as six float arrays (structure of arrays):
// a node's 8 children are consecutive nodes, so their boxes load 4 at a time.
struct NodeBounds {
  const float* lower[3] = {nullptr, nullptr, nullptr};
  const float* upper[3] = {nullptr, nullptr, nullptr};
  BoxBounds operator[](uint32_t n) const {
    return {{lower[0][n], lower[1][n], lower[2][n]}, {upper[0][n], upper[1][n], upper[2][n]}};
  }
};

// Drops from `keep` (bit i: child i of a node whose children start at `first_child`) the
// children whose blocks' bounds the ray cannot meet: MayHit for each, 4 children at a time
// with SSE2 (the same operations in the same order, so the same answers bit for bit).
inline uint32_t KeepMayHit(const RayBoxSetup& s, const NodeBounds& bounds, uint32_t first_child,
                           uint32_t keep, float tmin, float t_best) {
#if defined(__SSE2__)
  const float t_limit = NextUp(t_best) * bvh_internal::kFarScale;  // IntersectBox's t1
  for (int half = 0; half < 2; ++half) {
    if (((keep >> (4 * half)) & 0xfu) == 0) continue;
    const uint32_t at = first_child + 4u * static_cast<uint32_t>(half);
    __m128 t0 = _mm_set1_ps(tmin), t1 = _mm_set1_ps(t_limit);
    for (int a = 0; a < 3; ++a) {
      const __m128 lo = _mm_loadu_ps(bounds.lower[a] + at), hi = _mm_loadu_ps(bounds.upper[a] + at);
      const __m128 o = _mm_set1_ps(s.origin[a]), inv = _mm_set1_ps(s.inv_dir[a]);
      const __m128 pad = _mm_set1_ps(s.pad[a]);
      const __m128 t_near = _mm_sub_ps(_mm_mul_ps(_mm_sub_ps(s.dir_is_neg[a] ? hi : lo, o), inv), pad);
      const __m128 t_far = _mm_add_ps(
          _mm_mul_ps(_mm_mul_ps(_mm_sub_ps(s.dir_is_neg[a] ? lo : hi, o), inv),
                     _mm_set1_ps(bvh_internal::kFarScale)),
          pad);
      t0 = _mm_max_ps(t_near, t0);  // t_near > t0 ? t_near : t0, as IntersectBox
      t1 = _mm_min_ps(t_far, t1);   // t_far < t1 ? t_far : t1
    }
    const uint32_t missed = static_cast<uint32_t>(_mm_movemask_ps(_mm_cmpgt_ps(t0, t1)));
    keep &= ~(missed << (4 * half));
  }
#else
  for (uint32_t m = keep; m; m &= m - 1) {
    const int i = std::countr_zero(m);
    if (!MayHit(s, bounds[first_child + static_cast<uint32_t>(i)], tmin, t_best))
      keep &= ~(1u << i);
  }
#endif
  return keep;
}

// Cell of child `i` (Morton order: bit 0 = +x, bit 1 = +y, bit 2 = +z). The converter and
// every reader split cells with this one function, so cell bounds agree bit for bit.
inline Bounds3f ChildCell(const Bounds3f& parent, int i) {
  const Vec3f mid = (parent.lower + parent.upper) * 0.5f;
  Bounds3f c;
  c.lower = {(i & 1) ? mid.x : parent.lower.x, (i & 2) ? mid.y : parent.lower.y,
             (i & 4) ? mid.z : parent.lower.z};
  c.upper = {(i & 1) ? parent.upper.x : mid.x, (i & 2) ? parent.upper.y : mid.y,
             (i & 4) ? parent.upper.z : mid.z};
  return c;
}

// The children of an inner node with cell [lower, upper] (`children`: its 8 child nodes) that
// `s`'s ray meets within [tmin, t1]: returns their mask (bit i: child i, non-empty ones only)
// and writes each child's entry and (slack-widened, unclamped) exit distance, and the node's
// mid planes as ChildCell computes them. Every child face lies on one of 3 planes per axis
// (lower, mid, upper), so 9 near and 9 far slab distances, computed with IntersectBox's exact
// expressions and combined per child in its axis order (max/min selects, so NaN slabs of a ray
// lying in a plane are dropped alike), give each child exactly what its own box test would.
// SSE2 tests 4 children at a time.
inline uint32_t OctreeChildHits(const RayBoxSetup& s, float tmin, float t1, const float lower[3],
                                const float upper[3], const OctreeNode* children, float mid[3],
                                float enter[8], float exit[8]) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  float t_near[3][2], t_far[3][2];  // [axis][half of the child along that axis]
  for (int a = 0; a < 3; ++a) {
    mid[a] = (lower[a] + upper[a]) * 0.5f;
    const float planes[3] = {lower[a], mid[a], upper[a]};
    float tn[3], tf[3];
    for (int k = 0; k < 3; ++k) {
      tn[k] = (planes[k] - s.origin[a]) * s.inv_dir[a] - s.pad[a];
      tf[k] = (planes[k] - s.origin[a]) * s.inv_dir[a] * bvh_internal::kFarScale + s.pad[a];
    }
    for (int h = 0; h < 2; ++h) {
      t_near[a][h] = tn[s.dir_is_neg[a] ? h + 1 : h];
      t_far[a][h] = tf[s.dir_is_neg[a] ? h : h + 1];
    }
  }
  uint32_t keep = 0;
  for (int i = 0; i < 8; ++i) keep |= uint32_t{children[i].kind != kOctreeEmpty} << i;
#if defined(__SSE2__)
  const __m128 nx = _mm_setr_ps(t_near[0][0], t_near[0][1], t_near[0][0], t_near[0][1]);
  const __m128 ny = _mm_setr_ps(t_near[1][0], t_near[1][0], t_near[1][1], t_near[1][1]);
  const __m128 fx = _mm_setr_ps(t_far[0][0], t_far[0][1], t_far[0][0], t_far[0][1]);
  const __m128 fy = _mm_setr_ps(t_far[1][0], t_far[1][0], t_far[1][1], t_far[1][1]);
  const __m128 t0v = _mm_set1_ps(tmin), inf = _mm_set1_ps(kInf), t1v = _mm_set1_ps(t1);
  for (int z = 0; z < 2; ++z) {  // children 0-3 (lower z half), 4-7 (upper)
    // MAXPS(a, b) is a > b ? a : b and MINPS(a, b) is a < b ? a : b: the scalar selects.
    __m128 e = _mm_max_ps(nx, t0v);
    e = _mm_max_ps(ny, e);
    e = _mm_max_ps(_mm_set1_ps(t_near[2][z]), e);
    __m128 x = _mm_min_ps(fx, inf);
    x = _mm_min_ps(fy, x);
    x = _mm_min_ps(_mm_set1_ps(t_far[2][z]), x);
    const uint32_t missed =
        static_cast<uint32_t>(_mm_movemask_ps(_mm_cmpgt_ps(e, _mm_min_ps(x, t1v))));
    keep &= ~(missed << (4 * z));
    _mm_storeu_ps(enter + 4 * z, e);
    _mm_storeu_ps(exit + 4 * z, x);
  }
#else
  for (int i = 0; i < 8; ++i) {
    float e = tmin, x = kInf;
    for (int a = 0; a < 3; ++a) {
      const int h = (i >> a) & 1;
      e = t_near[a][h] > e ? t_near[a][h] : e;
      x = t_far[a][h] < x ? t_far[a][h] : x;
    }
    if (e > (x < t1 ? x : t1)) keep &= ~(1u << i);
    enter[i] = e;
    exit[i] = x;
  }
#endif
  return keep;
}

class OctreeView {
 public:
  OctreeView() = default;
  // `bounds`: per node, the union of its blocks' bounds (StoreReader computes it at open).
  OctreeView(std::span<const OctreeNode> nodes, NodeBounds bounds, Bounds3f root)
      : nodes_(nodes), bounds_(bounds), root_(root) {
    for (int a = 0; a < 3; ++a)
      magnitude_ = std::max({magnitude_, std::fabs(root.lower[a]), std::fabs(root.upper[a])});
  }

  std::span<const OctreeNode> nodes() const { return nodes_; }
  const NodeBounds& bounds() const { return bounds_; }
  const Bounds3f& root_cell() const { return root_; }
  // The largest |coordinate| of the root cell, which holds the model: the box tests' margin.
  float magnitude() const { return magnitude_; }

  // Calls visit(node_index, node, t_enter, t_exit) for every non-empty leaf the ray crosses
  // within [ray.tmin, *tmax] whose blocks' bounds it may meet (MayHit), nearest cell first.
  // The interval is widened by a few ulps so no hit on a cell boundary is lost. visit returns
  // false to stop; it may lower *tmax (closest hit): leaves entered after *tmax are skipped.
  // The visitor still tests each block of a leaf with several (MayHit on its own bounds), with
  // the same `setup`, which must be RayBoxSetup(ray, magnitude()).
  template <typename Visit>
  void VisitLeaves(const Ray& ray, const RayBoxSetup& setup, float* tmax, Visit&& visit) const;

 private:
  std::span<const OctreeNode> nodes_;
  NodeBounds bounds_;
  Bounds3f root_;
  float magnitude_ = 0;
};

template <typename Visit>
void OctreeView::VisitLeaves(const Ray& ray, const RayBoxSetup& setup, float* tmax,
                             Visit&& visit) const {
  if (nodes_.empty()) return;
  // A validated octree is at most kMaxOctreeDepth deep, so 8 pending children per level fit.
  // Items are plain floats, not Bounds3f: the stack is left uninitialised (its default
  // member initialisers cost more than the whole walk of a typical ray).
  constexpr int kMaxOctreeDepth = 32;
  struct Item {
    uint32_t node;
    float t_enter;
    float lower[3], upper[3];
  };
  Item stack[8 * kMaxOctreeDepth + 1];
  int top = 0;
  float t0;
  const float lo[3] = {root_.lower.x, root_.lower.y, root_.lower.z};
  const float hi[3] = {root_.upper.x, root_.upper.y, root_.upper.z};
  if (!IntersectBox(setup, lo, hi, ray.tmin, *tmax, &t0)) return;
  if (!MayHit(setup, bounds_[0], ray.tmin, *tmax)) return;
  stack[top++] = {0, t0, {lo[0], lo[1], lo[2]}, {hi[0], hi[1], hi[2]}};
  while (top > 0) {
    const Item item = stack[--top];
    // Same slack as IntersectBox: the best hit may have lowered *tmax since this was pushed.
    if (item.t_enter > *tmax * bvh_internal::kFarScale) continue;
    const OctreeNode& node = nodes_[item.node];
    if (node.kind == kOctreeLeaf) {
      float t_exit = *tmax;
      // The exit distance is only a hint for the visitor (the stopping rule uses entries).
      if (!visit(item.node, node, item.t_enter, t_exit)) return;
      continue;
    }
    if (node.kind != kOctreeInner) continue;
    float mid[3], enter[8], exit[8];
    uint32_t keep = OctreeChildHits(setup, ray.tmin, *tmax * bvh_internal::kFarScale, item.lower,
                                    item.upper, &nodes_[node.first], mid, enter, exit);
    keep = KeepMayHit(setup, bounds_, node.first, keep, ray.tmin, *tmax);
    // Children the ray meets, sorted far to near so the nearest is popped first.
    Item hits[8];
    int n = 0;
    for (; keep; keep &= keep - 1) {
      const int i = std::countr_zero(keep);
      Item& c = hits[n++];
      c.node = node.first + static_cast<uint32_t>(i);
      c.t_enter = enter[i];
      for (int a = 0; a < 3; ++a) {
        const bool upper_half = (i >> a) & 1;
        c.lower[a] = upper_half ? mid[a] : item.lower[a];
        c.upper[a] = upper_half ? item.upper[a] : mid[a];
      }
    }
    // Insertion sort, far to near (n <= 8), so the nearest child is popped first.
    for (int i = 1; i < n; ++i) {
      const Item x = hits[i];
      int j = i;
      for (; j > 0 && hits[j - 1].t_enter < x.t_enter; --j) hits[j] = hits[j - 1];
      hits[j] = x;
    }
    for (int i = 0; i < n; ++i) stack[top++] = hits[i];
  }
}

}  // namespace raystack::store
