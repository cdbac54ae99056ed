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
    // The midpoint as ChildCell computes it, so child cells agree bit for bit.
    const float mid[3] = {(item.lower[0] + item.upper[0]) * 0.5f,
                          (item.lower[1] + item.upper[1]) * 0.5f,
                          (item.lower[2] + item.upper[2]) * 0.5f};
    // Every child face lies on one of 3 planes per axis (lower, mid, upper), so the slab
    // distances IntersectBox would compute for the 8 children are 9 near and 9 far values,
    // computed once here with IntersectBox's exact expressions and combined per child in
    // its order: the same results for a fraction of the work.
    float t_near[3][3], t_far[3][3];  // [axis][plane: 0 lower, 1 mid, 2 upper]
    for (int a = 0; a < 3; ++a) {
      const float planes[3] = {item.lower[a], mid[a], item.upper[a]};
      for (int k = 0; k < 3; ++k) {
        t_near[a][k] = (planes[k] - setup.origin[a]) * setup.inv_dir[a];
        t_far[a][k] = (planes[k] - setup.origin[a]) * setup.inv_dir[a] * bvh_internal::kFarScale;
      }
    }
    const float t1_limit = *tmax * bvh_internal::kFarScale;
    // Children the ray meets, sorted far to near so the nearest is popped first.
    Item hits[8];
    int n = 0;
    for (int i = 0; i < 8; ++i) {
      if (nodes_[node.first + i].kind == kOctreeEmpty) continue;
      float enter = ray.tmin, exit = t1_limit;
      for (int a = 0; a < 3; ++a) {
        // Child i spans planes [0, 1] or [1, 2] on axis a; the near one depends on the sign.
        const int half = (i >> a) & 1;
        const int near_plane = setup.dir_is_neg[a] ? half + 1 : half;
        const int far_plane = setup.dir_is_neg[a] ? half : half + 1;
        const float tn = t_near[a][near_plane], tf = t_far[a][far_plane];
        enter = tn > enter ? tn : enter;
        exit = tf < exit ? tf : exit;
      }
      if (enter > exit) continue;
      Item& c = hits[n++];
      c.node = node.first + static_cast<uint32_t>(i);
      c.t_enter = enter;
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
