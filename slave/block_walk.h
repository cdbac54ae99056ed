#pragma once
// Which block a ray needs next. A waiting ray keeps no pointer into the octree, only a resume
// point: (t, skip). The walk drops every leaf the ray leaves before t, then skips `skip`
// blocks; the first block after those is next. Dropping leaves by their exit distance keeps
// the order of the rest exactly that of a full front-to-back walk (the same entry distances,
// sorted the same way), so a resumed ray visits exactly the blocks, in the order, that an
// uninterrupted one would, whatever happened in between; and the walk costs O(depth) instead
// of re-walking every leaf already traversed.
//
// After block B of a leaf entered at t_B, the resume point is t = t_B, skip = the blocks of
// the walk up to and including B that leave at or after t_B (B's leaf-mates before it and the
// few leaves touching the point where the ray enters B's leaf). A closer hit found later only
// removes blocks from the end of the order (cells along a ray are entered in order).

#include <cstdint>
#include <limits>

#include "common/base/check.h"
#include "common/geometry/bvh.h"
#include "common/geometry/ray.h"
#include "common/store/octree.h"

namespace raystack::slave {

struct NextBlock {
  uint32_t block = kInvalidId;  // kInvalidId: the ray has no more blocks to traverse
  float resume_t = 0;            // the resume point once `block` is traversed
  uint32_t skip = 0;
};

inline NextBlock FindNextBlock(const store::OctreeView& octree, const Ray& ray, float tmax,
                               float resume_t, uint32_t skip) {
  NextBlock out;
  const auto nodes = octree.nodes();
  if (nodes.empty()) return out;
  const RayBoxSetup setup(ray);
  const float t1_limit = tmax * bvh_internal::kFarScale;
  constexpr int kMaxOctreeDepth = 32;
  struct Item {
    uint32_t node;
    float t_enter, t_exit;  // t_exit: unclamped by tmax, so it does not change as hits shrink it
    float lower[3], upper[3];
  };
  Item stack[8 * kMaxOctreeDepth + 1];
  int top = 0;
  // Leaves already skipped: (exit, blocks), to count which survive at the new resume point.
  // Only leaves touching one point can precede the next block, so a few entries suffice.
  constexpr int kMaxSkipped = 64;
  float skipped_exit[kMaxSkipped];
  uint32_t skipped_blocks[kMaxSkipped];
  int skipped = 0;

  // Entry and (slack-widened) exit of the box [lo, hi], with the expressions the children use.
  auto slabs = [&](const float lo[3], const float hi[3], float* enter, float* exit) {
    *enter = ray.tmin;
    *exit = std::numeric_limits<float>::infinity();
    for (int a = 0; a < 3; ++a) {
      const float near_plane = setup.dir_is_neg[a] ? hi[a] : lo[a];
      const float far_plane = setup.dir_is_neg[a] ? lo[a] : hi[a];
      const float tn = (near_plane - setup.origin[a]) * setup.inv_dir[a];
      const float tf = (far_plane - setup.origin[a]) * setup.inv_dir[a] * bvh_internal::kFarScale;
      *enter = tn > *enter ? tn : *enter;
      *exit = tf < *exit ? tf : *exit;
    }
  };
  const Bounds3f root = octree.root_cell();
  Item first{0, 0, 0, {root.lower.x, root.lower.y, root.lower.z}, {root.upper.x, root.upper.y, root.upper.z}};
  slabs(first.lower, first.upper, &first.t_enter, &first.t_exit);
  if (first.t_enter > (first.t_exit < t1_limit ? first.t_exit : t1_limit) || first.t_exit < resume_t)
    return out;
  stack[top++] = first;
  while (top > 0) {
    const Item item = stack[--top];
    if (item.t_enter > t1_limit) continue;
    const store::OctreeNode& node = nodes[item.node];
    if (node.kind == store::kOctreeLeaf) {
      if (skip >= node.count) {
        CHECK(skipped < kMaxSkipped);
        skipped_exit[skipped] = item.t_exit;
        skipped_blocks[skipped++] = node.count;
        skip -= node.count;
        continue;
      }
      out.block = node.first + skip;
      out.resume_t = item.t_enter;
      uint64_t survivors = uint64_t{skip} + 1;
      for (int i = 0; i < skipped; ++i)
        if (!(skipped_exit[i] < item.t_enter)) survivors += skipped_blocks[i];
      CHECK(survivors <= kMaxSkip);
      out.skip = static_cast<uint32_t>(survivors);
      return out;
    }
    if (node.kind != store::kOctreeInner) continue;
    const float mid[3] = {(item.lower[0] + item.upper[0]) * 0.5f,
                          (item.lower[1] + item.upper[1]) * 0.5f,
                          (item.lower[2] + item.upper[2]) * 0.5f};
    Item hits[8];
    int n = 0;
    for (int i = 0; i < 8; ++i) {
      if (nodes[node.first + i].kind == store::kOctreeEmpty) continue;
      Item c;
      c.node = node.first + static_cast<uint32_t>(i);
      for (int a = 0; a < 3; ++a) {
        const bool upper_half = (i >> a) & 1;
        c.lower[a] = upper_half ? mid[a] : item.lower[a];
        c.upper[a] = upper_half ? item.upper[a] : mid[a];
      }
      slabs(c.lower, c.upper, &c.t_enter, &c.t_exit);
      if (c.t_enter > (c.t_exit < t1_limit ? c.t_exit : t1_limit)) continue;  // missed
      if (c.t_exit < resume_t) continue;  // left behind before the resume point
      hits[n++] = c;
    }
    // Far to near, so the nearest is popped first; ties keep child order (as in every walk).
    for (int i = 1; i < n; ++i) {
      const Item x = hits[i];
      int j = i;
      for (; j > 0 && hits[j - 1].t_enter < x.t_enter; --j) hits[j] = hits[j - 1];
      hits[j] = x;
    }
    for (int i = 0; i < n; ++i) stack[top++] = hits[i];
  }
  return out;
}

}  // namespace raystack::slave
