#pragma once
// Which block a ray needs next. The blocks a ray crosses come in the order of one depth-first
// walk of the level-1 octree that visits each node's children nearest first: by entry distance,
// then by exit distance (a cell the ray only touches at the point where it enters a sibling
// comes before that sibling), then by higher child index. Cells are disjoint, so the order is
// monotone in entry distance and a ray can stop at the first block entered past its closest
// hit. The walk is a pure function of the ray, so the modes, threads and ranks that trace a
// ray in pieces all visit the same blocks in the same order.
//
// Blocks whose bounds (the index's copy of their BVH root box) the ray misses are left out,
// and so are octree nodes whose blocks' bounds it misses all together (store::MayHit): such a
// block could not change the ray's hit, so it is neither waited for nor loaded.
//
// A waiting ray keeps no walk state: the queue it waits in names its block, and the next block
// is that block's successor in the walk, found by climbing from the block's leaf only as far
// as a later sibling exists (usually a level or two), never from the root again. Children are
// tested with the store's OctreeChildHits (IntersectBox's exact expressions and slack, 4
// children at a time), so no hit on a cell boundary is lost.
//
// A ray that starts inside the octree (a shadow or a bounced ray, a camera inside the model)
// does not walk down from the root: the walk's first leaf is the cell holding its start, found
// by point location, whenever that start lies clear of the cell's faces by the box tests'
// margin (every sibling on the way down is then entered strictly later, or missed). From that
// cell the walk resumes as Next does, so the blocks and their order are the same bit for bit.
//
// Thread-safe after construction (read-only).

#include <algorithm>
#include <bit>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "common/base/check.h"
#include "common/geometry/bvh.h"
#include "common/geometry/ray.h"
#include "common/store/format.h"
#include "common/store/octree.h"

namespace raystack::slave {

class BlockWalk {
 public:
  BlockWalk(const store::OctreeView& octree, std::span<const store::BlockEntry> blocks);
  // (The octree's node bounds are used, so `octree` must come from the same store as `blocks`.)

  // The first block along `ray` within [ray.tmin, ray.tmax], or kInvalidId.
  uint32_t First(const Ray& ray) const;
  // The block after `block` along `ray`, whose closest hit so far is ray.tmax, or kInvalidId
  // when no later block is entered before it.
  uint32_t Next(const Ray& ray, uint32_t block) const;
  // A cheap early answer to Next: true when `block` is its leaf's last and the closest hit lies
  // clearly before the ray leaves that leaf (every later leaf starts where this one ends). The
  // margin covers the few ulps by which the walk's distances may differ; a ray near it walks.
  bool DoneAfter(const Ray& ray, uint32_t block) const;

 private:
  static constexpr int kMaxDepth = 32;  // validated octrees are shallower
  struct Cell {
    float lower[3], upper[3];
  };
  // One level of the depth-first walk: a node's cell and its children still to visit, as
  // compact entries in reverse visiting order (the next one last).
  struct Frame {
    Cell cell;
    float mid[3];
    uint32_t first;  // the node's first child
    int count;
    float t_enter[8], t_exit[8];  // t_exit unclamped by tmax: it does not change as hits do
    uint8_t child[8];
  };
  struct Slabs;  // a ray's box-test constants

  // Entry and exit of the 8 children of a node with cell `cell`; returns the mask of those
  // the ray meets before t1 (non-empty ones only).
  uint32_t Children(const Slabs& s, uint32_t first_child, const Cell& cell, float mid[3],
                    float enter[8], float exit[8]) const;
  // The first block of `leaf` from `from` on whose bounds the ray may meet, or kInvalidId.
  uint32_t FirstMet(const Slabs& s, const store::OctreeNode& leaf, uint32_t from) const;
  // Pushes the children in `keep` onto a new frame, in visiting order.
  static void Push(Frame* f, uint32_t keep, const float enter[8], const float exit[8]);
  // Continues the walk on `frames`; returns the first block of the next leaf, or kInvalidId.
  uint32_t Descend(const Slabs& s, Frame* frames, int depth) const;
  // The first block after the subtree of `node` (any node but the root): climbs through its
  // ancestors, visiting at each the children the walk visits after the one it comes from.
  uint32_t Climb(const Slabs& s, uint32_t node) const;
  // The leaf or empty node whose cell holds the ray's start when the walk from the root is
  // sure to visit it first (see the file comment), or kInvalidId.
  uint32_t StartCell(const Slabs& s, const Ray& ray) const;

  std::span<const store::OctreeNode> nodes_;
  store::NodeBounds node_bounds_;
  std::span<const store::BlockEntry> blocks_;
  Cell root_;
  float magnitude_;               // the octree's, for the box tests' margin
  std::vector<uint32_t> parent_;  // by node; the root's is itself
  std::vector<Cell> cells_;       // by node: its cell (ChildCell's arithmetic from the root)
};

// ---------------------------------------------------------------------------------------------

struct BlockWalk::Slabs {
  Slabs(const Ray& ray, float magnitude)
      : box(ray, magnitude), tmin(ray.tmin), t1(ray.tmax * bvh_internal::kFarScale),
        t_best(ray.tmax) {}
  RayBoxSetup box;
  float tmin, t1;
  float t_best;  // the closest hit so far, for store::MayHit
};

// Visiting order of two children of one node (a before b), for keys (enter, exit, child).
inline bool VisitsBefore(float enter_a, float exit_a, int child_a, float enter_b, float exit_b,
                         int child_b) {
  if (enter_a != enter_b) return enter_a < enter_b;
  if (exit_a != exit_b) return exit_a < exit_b;
  return child_a > child_b;
}

inline uint32_t BlockWalk::Children(const Slabs& s, uint32_t first_child, const Cell& cell,
                                    float mid[3], float enter[8], float exit[8]) const {
  const uint32_t keep = store::OctreeChildHits(s.box, s.tmin, s.t1, cell.lower, cell.upper,
                                               &nodes_[first_child], mid, enter, exit);
  return store::KeepMayHit(s.box, node_bounds_, first_child, keep, s.tmin, s.t_best);
}

inline uint32_t BlockWalk::FirstMet(const Slabs& s, const store::OctreeNode& leaf,
                                    uint32_t from) const {
  for (uint32_t b = from; b < leaf.first + leaf.count; ++b)
    if (store::MayHit(s.box, store::BoundsOf(blocks_[b]), s.tmin, s.t_best)) return b;
  return kInvalidId;
}

inline void BlockWalk::Push(Frame* f, uint32_t keep, const float enter[8], const float exit[8]) {
  f->count = 0;
  for (; keep; keep &= keep - 1) {
    const int i = std::countr_zero(keep);
    int j = f->count++;
    for (; j > 0 && VisitsBefore(f->t_enter[j - 1], f->t_exit[j - 1], f->child[j - 1], enter[i],
                                 exit[i], i);
         --j) {
      f->t_enter[j] = f->t_enter[j - 1];
      f->t_exit[j] = f->t_exit[j - 1];
      f->child[j] = f->child[j - 1];
    }
    f->t_enter[j] = enter[i];
    f->t_exit[j] = exit[i];
    f->child[j] = static_cast<uint8_t>(i);
  }
}

inline uint32_t BlockWalk::Descend(const Slabs& s, Frame* frames, int depth) const {
  float enter[8], exit[8];
  while (depth > 0) {
    Frame& f = frames[depth - 1];
    if (f.count == 0) {
      --depth;
      continue;
    }
    const int k = --f.count;
    const int i = f.child[k];
    const uint32_t index = f.first + static_cast<uint32_t>(i);
    const store::OctreeNode& node = nodes_[index];
    if (node.kind == store::kOctreeLeaf) {
      // Children() kept this leaf by its bounds, the union of its blocks': one block's own
      // test would repeat it.
      if (node.count == 1) return node.first;
      const uint32_t block = FirstMet(s, node, node.first);
      if (block != kInvalidId) return block;
      continue;
    }
    // An inner child (empty ones were never pushed): its children become the next frame.
    CHECK(depth < kMaxDepth);
    Frame& c = frames[depth++];
    for (int a = 0; a < 3; ++a) {
      const bool upper_half = (i >> a) & 1;
      c.cell.lower[a] = upper_half ? f.mid[a] : f.cell.lower[a];
      c.cell.upper[a] = upper_half ? f.cell.upper[a] : f.mid[a];
    }
    c.first = node.first;
    Push(&c, Children(s, node.first, c.cell, c.mid, enter, exit), enter, exit);
  }
  return kInvalidId;
}

inline uint32_t BlockWalk::StartCell(const Slabs& s, const Ray& ray) const {
  // Point location: child i holds the upper half along axis a when bit a of i is set, and
  // child 7's lower corner is the node's mid point.
  uint32_t n = 0;
  const Vec3f& o = s.box.origin;
  while (nodes_[n].kind == store::kOctreeInner) {
    const Cell& upper_child = cells_[nodes_[n].first + 7];
    n = nodes_[n].first + static_cast<uint32_t>((o.x >= upper_child.lower[0]) |
                                                ((o.y >= upper_child.lower[1]) << 1) |
                                                ((o.z >= upper_child.lower[2]) << 2));
  }
  // The cell is first if, on every axis, with the expressions of the box tests: its face
  // ahead is entered after tmin (so is every face ahead of it, the near faces of the siblings
  // on that side, at every level up), and its face behind is left before tmin (every sibling
  // on that side is missed). Then that face is also entered before tmin (pads are >= 0), so
  // the cell and each ancestor are entered at exactly tmin, before any sibling. A NaN
  // anywhere fails a comparison: the walk starts at the root.
  if (!(ray.tmin >= 0 && ray.tmin <= ray.tmax)) return kInvalidId;
  const Cell& c = cells_[n];
  for (int a = 0; a < 3; ++a) {
    const float ahead = s.box.dir_is_neg[a] ? c.lower[a] : c.upper[a];
    const float behind = s.box.dir_is_neg[a] ? c.upper[a] : c.lower[a];
    const float t_ahead = (ahead - s.box.origin[a]) * s.box.inv_dir[a];
    const float t_behind = (behind - s.box.origin[a]) * s.box.inv_dir[a];
    if (!(t_ahead - s.box.pad[a] > ray.tmin)) return kInvalidId;
    if (!(t_behind * bvh_internal::kFarScale + s.box.pad[a] < ray.tmin)) return kInvalidId;
  }
  return n;
}

inline uint32_t BlockWalk::First(const Ray& ray) const {
  if (nodes_.empty()) return kInvalidId;
  const Slabs s(ray, magnitude_);
  if (const uint32_t start = StartCell(s, ray); start != kInvalidId) {
    // The walk from the root would reach this cell first, having tested its bounds and every
    // ancestor's; its blocks' own bounds lie inside those, so testing them alone is the same.
    const store::OctreeNode& node = nodes_[start];
    if (node.kind == store::kOctreeLeaf) {
      const uint32_t block = FirstMet(s, node, node.first);
      if (block != kInvalidId) return block;
    }
    return Climb(s, start);  // (nothing after the root)
  }
  float enter;
  if (!IntersectBox(s.box, root_.lower, root_.upper, s.tmin, ray.tmax, &enter)) return kInvalidId;
  if (!store::MayHit(s.box, node_bounds_[0], s.tmin, s.t_best)) return kInvalidId;
  const store::OctreeNode& root = nodes_[0];
  if (root.kind == store::kOctreeLeaf) return FirstMet(s, root, root.first);
  if (root.kind != store::kOctreeInner) return kInvalidId;
  Frame frames[kMaxDepth];
  float e[8], x[8];
  frames[0].cell = root_;
  frames[0].first = root.first;
  Push(&frames[0], Children(s, root.first, root_, frames[0].mid, e, x), e, x);
  return Descend(s, frames, 1);
}

inline uint32_t BlockWalk::Next(const Ray& ray, uint32_t block) const {
  const uint32_t leaf = blocks_[block].octree_leaf;
  const Slabs s(ray, magnitude_);
  const uint32_t mate = FirstMet(s, nodes_[leaf], block + 1);
  if (mate != kInvalidId) return mate;
  return Climb(s, leaf);
}

inline uint32_t BlockWalk::Climb(const Slabs& s, uint32_t node) const {
  // At each ancestor, the children visited after the one we come from, in order. The climb
  // usually ends a level or two up, so ancestors are only visited as far as needed.
  Frame frames[kMaxDepth];
  float enter[8], exit[8];
  for (uint32_t child = node; child != 0;) {
    const uint32_t parent = parent_[child];
    const uint32_t first = nodes_[parent].first;
    const int from = static_cast<int>(child - first);
    Frame& f = frames[0];
    f.cell = cells_[parent];
    f.first = first;
    uint32_t keep = Children(s, first, f.cell, f.mid, enter, exit);
    for (uint32_t m = keep; m; m &= m - 1) {
      const int i = std::countr_zero(m);
      if (!VisitsBefore(enter[from], exit[from], from, enter[i], exit[i], i))
        keep &= ~(1u << i);
    }
    Push(&f, keep, enter, exit);
    const uint32_t found = Descend(s, frames, 1);
    if (found != kInvalidId) return found;
    child = parent;
  }
  return kInvalidId;
}

inline bool BlockWalk::DoneAfter(const Ray& ray, uint32_t block) const {
  const store::BlockEntry& e = blocks_[block];
  const store::OctreeNode& leaf = nodes_[e.octree_leaf];
  if (block + 1 != leaf.first + leaf.count) return false;
  float exit = std::numeric_limits<float>::infinity();
  Vec3f inv;
  for (int a = 0; a < 3; ++a) {
    inv[a] = 1.0f / ray.direction[a];
    const float far_plane = inv[a] < 0 ? e.cell_lower[a] : e.cell_upper[a];
    const float tf = (far_plane - ray.origin[a]) * inv[a];
    exit = tf < exit ? tf : exit;
  }
  // Later cells are entered up to the box tests' margin before this one's exit.
  float pad[3];
  BoxMarginPads(ray, inv, magnitude_, pad);
  exit -= std::max({pad[0], pad[1], pad[2]});
  constexpr float kMargin = 1.0f - 1e-5f;
  return exit > 0 && ray.tmax * bvh_internal::kFarScale < exit * kMargin;
}

}  // namespace raystack::slave
