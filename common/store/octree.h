#pragma once
// The level-1 octree (the "management level", always in RAM): which cells exist, which are
// empty, and which blocks fill each leaf. It answers two questions for a ray: which leaves it
// crosses, front to back, and where each starts and ends along the ray.

#include <cstdint>
#include <span>

#include "common/geometry/bounds.h"
#include "common/geometry/bvh.h"
#include "common/geometry/ray.h"
#include "common/store/format.h"

namespace raystack::store {

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

class OctreeView {
 public:
  OctreeView() = default;
  OctreeView(std::span<const OctreeNode> nodes, Bounds3f root) : nodes_(nodes), root_(root) {}

  std::span<const OctreeNode> nodes() const { return nodes_; }
  const Bounds3f& root_cell() const { return root_; }

  // Calls visit(node_index, node, t_enter, t_exit) for every non-empty leaf the ray crosses
  // within [ray.tmin, *tmax], nearest first. The interval is widened by a few ulps so no hit
  // on a cell boundary is lost. visit returns false to stop; it may lower *tmax (closest hit):
  // leaves entered after *tmax are skipped.
  template <typename Visit>
  void VisitLeaves(const Ray& ray, float* tmax, Visit&& visit) const;

 private:
  std::span<const OctreeNode> nodes_;
  Bounds3f root_;
};

template <typename Visit>
void OctreeView::VisitLeaves(const Ray& ray, float* tmax, Visit&& visit) const {
  if (nodes_.empty()) return;
  const RayBoxSetup setup(ray);
  // A validated octree is at most kMaxOctreeDepth deep, so 8 pending children per level fit.
  constexpr int kMaxOctreeDepth = 32;
  struct Item { uint32_t node; Bounds3f cell; float t_enter; };
  Item stack[8 * kMaxOctreeDepth + 1];
  int top = 0;
  float t0;
  const float lo[3] = {root_.lower.x, root_.lower.y, root_.lower.z};
  const float hi[3] = {root_.upper.x, root_.upper.y, root_.upper.z};
  if (!IntersectBox(setup, lo, hi, ray.tmin, *tmax, &t0)) return;
  stack[top++] = {0, root_, t0};
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
    // Children the ray meets, sorted far to near so the nearest is popped first.
    Item hits[8];
    int n = 0;
    for (int i = 0; i < 8; ++i) {
      if (nodes_[node.first + i].kind == kOctreeEmpty) continue;
      const Bounds3f c = ChildCell(item.cell, i);
      const float clo[3] = {c.lower.x, c.lower.y, c.lower.z};
      const float chi[3] = {c.upper.x, c.upper.y, c.upper.z};
      float te;
      if (IntersectBox(setup, clo, chi, ray.tmin, *tmax, &te))
        hits[n++] = {node.first + static_cast<uint32_t>(i), c, te};
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
