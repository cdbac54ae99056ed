#pragma once
// Which block a ray needs next. A waiting ray keeps no pointer into the octree, only a resume
// point: (t, skip). The walk drops every leaf the ray leaves before t, then skips `skip`
// blocks; the first block after those is next. This is exact because the walk's order is
// monotone in entry distance: children are visited by entry, and among equal entries by exit,
// so a cell the ray only touches at a corner where it enters a sibling comes before that
// sibling (visited after it, the touched cell would be left "before t" and lost). Disjoint
// cells then make every later leaf start where earlier ones end, and the far-plane slack
// covers rounding. A resumed ray visits exactly the blocks, in the order, of an uninterrupted
// walk, whatever happened in between, and each step costs O(depth) instead of re-walking
// every leaf already traversed.
//
// After block B of a leaf entered at t_B, the resume point is t = t_B, skip = the blocks of
// the walk up to and including B that leave at or after t_B (B's leaf-mates before it and the
// few leaves touching the point where the ray enters B's leaf). A closer hit found later only
// removes blocks from the end of the order (cells along a ray are entered in order).

#include <bit>
#include <cstdint>
#include <limits>
#include <vector>

#include "common/base/check.h"
#include "common/geometry/bvh.h"
#include "common/geometry/ray.h"
#include "common/store/octree.h"
#include "slave/ray_record.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

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
  constexpr float kInf = std::numeric_limits<float>::infinity();
  // One frame per level of the current path: the node's cell once, and its children the ray
  // meets as compact entries, sorted far to near (consumed from the end, nearest first; among
  // equal entries the later child first). Cells of children are derived when visited, so the
  // walk moves 12 bytes per child instead of a whole cell.
  constexpr int kMaxOctreeDepth = 32;
  struct Frame {
    float lower[3], mid[3], upper[3];
    uint32_t first;  // the node's first child
    int count;       // entries not yet visited
    float t_enter[8], t_exit[8];  // t_exit: unclamped by tmax, so later hits do not change it
    uint8_t child[8];
  };
  Frame frames[kMaxOctreeDepth + 1];
  int depth = 0;
  // Leaves already skipped: (exit, blocks), to count which survive at the new resume point.
  // Only leaves touching one point can precede the next block, so a few entries suffice.
  constexpr int kMaxSkipped = 64;
  float skipped_exit[kMaxSkipped];
  uint32_t skipped_blocks[kMaxSkipped];
  int skipped = 0;

  // Visits node `index` with cell [lo, hi] entered at t_enter: a leaf yields the next block
  // or is skipped; an inner node becomes the next frame. Returns true when `out` is set.
  auto visit = [&](uint32_t index, const float lo[3], const float hi[3], float t_enter,
                   float t_exit) -> bool {
    const store::OctreeNode& node = nodes[index];
    if (node.kind == store::kOctreeLeaf) {
      if (skip >= node.count) {
        CHECK(skipped < kMaxSkipped);
        skipped_exit[skipped] = t_exit;
        skipped_blocks[skipped++] = node.count;
        skip -= node.count;
        return false;
      }
      out.block = node.first + skip;
      out.resume_t = t_enter;
      uint64_t survivors = uint64_t{skip} + 1;
      for (int i = 0; i < skipped; ++i)
        if (!(skipped_exit[i] < t_enter)) survivors += skipped_blocks[i];
      CHECK(survivors <= kMaxSkip);
      out.skip = static_cast<uint32_t>(survivors);
      return true;
    }
    if (node.kind != store::kOctreeInner) return false;
    CHECK(depth < kMaxOctreeDepth);
    Frame& f = frames[depth++];
    f.first = node.first;
    f.count = 0;
    // Children's faces lie on 3 planes per axis (lower, mid, upper): 9 near and 9 far slab
    // distances, computed once with IntersectBox's expressions and combined per child, give
    // each child exactly what a box test of its own would (the walk stays a pure function).
    float t_near[3][2], t_far[3][2];  // [axis][half of the child along that axis]
    for (int a = 0; a < 3; ++a) {
      f.lower[a] = lo[a];
      f.upper[a] = hi[a];
      f.mid[a] = (lo[a] + hi[a]) * 0.5f;  // as ChildCell computes it
      const float planes[3] = {lo[a], f.mid[a], hi[a]};
      float tn[3], tf[3];
      for (int k = 0; k < 3; ++k) {
        tn[k] = (planes[k] - setup.origin[a]) * setup.inv_dir[a];
        tf[k] = (planes[k] - setup.origin[a]) * setup.inv_dir[a] * bvh_internal::kFarScale;
      }
      for (int h = 0; h < 2; ++h) {
        t_near[a][h] = tn[setup.dir_is_neg[a] ? h + 1 : h];
        t_far[a][h] = tf[setup.dir_is_neg[a] ? h : h + 1];
      }
    }
    // The 8 children's entries and exits (the max/min chains of IntersectBox, in its axis
    // order), then which ones the ray meets at or after the resume point.
    float enter[8], exit[8];
    uint32_t keep = 0;
    for (int i = 0; i < 8; ++i)
      keep |= uint32_t{nodes[node.first + i].kind != store::kOctreeEmpty} << i;
#if defined(__SSE2__)
    {
      const __m128 nx = _mm_setr_ps(t_near[0][0], t_near[0][1], t_near[0][0], t_near[0][1]);
      const __m128 ny = _mm_setr_ps(t_near[1][0], t_near[1][0], t_near[1][1], t_near[1][1]);
      const __m128 fx = _mm_setr_ps(t_far[0][0], t_far[0][1], t_far[0][0], t_far[0][1]);
      const __m128 fy = _mm_setr_ps(t_far[1][0], t_far[1][0], t_far[1][1], t_far[1][1]);
      const __m128 tmin = _mm_set1_ps(ray.tmin), inf = _mm_set1_ps(kInf);
      const __m128 t1 = _mm_set1_ps(t1_limit), resume = _mm_set1_ps(resume_t);
      for (int z = 0; z < 2; ++z) {  // children 0-3 (lower z half), 4-7 (upper)
        // MAXPS(a, b) is a > b ? a : b and MINPS(a, b) is a < b ? a : b: the scalar selects.
        __m128 e = _mm_max_ps(nx, tmin);
        e = _mm_max_ps(ny, e);
        e = _mm_max_ps(_mm_set1_ps(t_near[2][z]), e);
        __m128 x = _mm_min_ps(fx, inf);
        x = _mm_min_ps(fy, x);
        x = _mm_min_ps(_mm_set1_ps(t_far[2][z]), x);
        const __m128 missed = _mm_cmpgt_ps(e, _mm_min_ps(x, t1));
        const __m128 behind = _mm_cmplt_ps(x, resume);
        const uint32_t drop = static_cast<uint32_t>(_mm_movemask_ps(_mm_or_ps(missed, behind)));
        keep &= ~(drop << (4 * z));
        _mm_storeu_ps(enter + 4 * z, e);
        _mm_storeu_ps(exit + 4 * z, x);
      }
    }
#else
    for (int i = 0; i < 8; ++i) {
      float e = ray.tmin, x = kInf;
      for (int a = 0; a < 3; ++a) {
        const int h = (i >> a) & 1;
        e = t_near[a][h] > e ? t_near[a][h] : e;
        x = t_far[a][h] < x ? t_far[a][h] : x;
      }
      if (e > (x < t1_limit ? x : t1_limit) || x < resume_t) keep &= ~(1u << i);
      enter[i] = e;
      exit[i] = x;
    }
#endif
    for (; keep; keep &= keep - 1) {
      const int i = std::countr_zero(keep);
      // Insertion, last-visited first: by entry, then by exit, so that a cell the ray only
      // touches where it enters another is visited before that one (see the top).
      int j = f.count++;
      for (; j > 0 && (f.t_enter[j - 1] < enter[i] ||
                       (f.t_enter[j - 1] == enter[i] && f.t_exit[j - 1] < exit[i]));
           --j) {
        f.t_enter[j] = f.t_enter[j - 1];
        f.t_exit[j] = f.t_exit[j - 1];
        f.child[j] = f.child[j - 1];
      }
      f.t_enter[j] = enter[i];
      f.t_exit[j] = exit[i];
      f.child[j] = static_cast<uint8_t>(i);
    }
    return false;
  };

  // The root cell, with the expressions IntersectBox uses.
  const Bounds3f root = octree.root_cell();
  const float root_lo[3] = {root.lower.x, root.lower.y, root.lower.z};
  const float root_hi[3] = {root.upper.x, root.upper.y, root.upper.z};
  float root_enter = ray.tmin, root_exit = kInf;
  for (int a = 0; a < 3; ++a) {
    const float near_plane = setup.dir_is_neg[a] ? root_hi[a] : root_lo[a];
    const float far_plane = setup.dir_is_neg[a] ? root_lo[a] : root_hi[a];
    const float tn = (near_plane - setup.origin[a]) * setup.inv_dir[a];
    const float tf = (far_plane - setup.origin[a]) * setup.inv_dir[a] * bvh_internal::kFarScale;
    root_enter = tn > root_enter ? tn : root_enter;
    root_exit = tf < root_exit ? tf : root_exit;
  }
  if (root_enter > (root_exit < t1_limit ? root_exit : t1_limit) || root_exit < resume_t)
    return out;
  if (visit(0, root_lo, root_hi, root_enter, root_exit)) return out;
  while (depth > 0) {
    Frame& f = frames[depth - 1];
    if (f.count == 0) {
      --depth;
      continue;
    }
    const int k = --f.count;
    const int i = f.child[k];
    float lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
      const bool upper_half = (i >> a) & 1;
      lo[a] = upper_half ? f.mid[a] : f.lower[a];
      hi[a] = upper_half ? f.upper[a] : f.mid[a];
    }
    if (visit(f.first + static_cast<uint32_t>(i), lo, hi, f.t_enter[k], f.t_exit[k])) return out;
  }
  return out;
}

// The cell of each block's octree leaf, by block id, and whether the block is the last of its
// leaf: enough to see, right after a block, that a ray's walk is over without walking again.
struct BlockCell {
  float lower[3], upper[3];
  bool last_in_leaf;
};

inline std::vector<BlockCell> BlockCells(const store::OctreeView& octree, size_t block_count) {
  std::vector<BlockCell> cells(block_count, BlockCell{{0, 0, 0}, {0, 0, 0}, false});
  const auto nodes = octree.nodes();
  if (nodes.empty()) return cells;
  struct Item {
    uint32_t node;
    Bounds3f cell;
  };
  std::vector<Item> stack{{0, octree.root_cell()}};
  while (!stack.empty()) {
    const Item item = stack.back();
    stack.pop_back();
    const store::OctreeNode& node = nodes[item.node];
    if (node.kind == store::kOctreeInner) {
      for (int i = 0; i < 8; ++i)
        stack.push_back({node.first + static_cast<uint32_t>(i), store::ChildCell(item.cell, i)});
    } else if (node.kind == store::kOctreeLeaf) {
      for (uint32_t b = node.first; b < node.first + node.count && b < block_count; ++b)
        cells[b] = {{item.cell.lower.x, item.cell.lower.y, item.cell.lower.z},
                    {item.cell.upper.x, item.cell.upper.y, item.cell.upper.z},
                    b + 1 == node.first + node.count};
    }
  }
  return cells;
}

// True when, after `block`, FindNextBlock would find nothing: the block is its leaf's last and
// the closest hit (ray.tmax) lies clearly before the ray leaves that leaf, while every leaf
// later in the walk is entered where this one is left (cells are disjoint). The margin covers
// the few ulps by which the walk's slab distances may differ; a ray near it walks as usual.
// (A leaf met only at the very point where the ray enters this one, a ray through an edge,
// is not waited for: a hit there is on this leaf's boundary.)
inline bool DoneAfterBlock(const std::vector<BlockCell>& cells, const Ray& ray, uint32_t block) {
  const BlockCell& c = cells[block];
  if (!c.last_in_leaf) return false;
  float exit = std::numeric_limits<float>::infinity();
  for (int a = 0; a < 3; ++a) {
    const float inv = 1.0f / ray.direction[a];
    const float far_plane = inv < 0 ? c.lower[a] : c.upper[a];
    const float tf = (far_plane - ray.origin[a]) * inv;
    exit = tf < exit ? tf : exit;
  }
  constexpr float kMargin = 1.0f - 1e-5f;
  return exit > 0 && ray.tmax * bvh_internal::kFarScale < exit * kMargin;
}

}  // namespace raystack::slave
