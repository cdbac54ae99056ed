#include "slave/block_walk.h"

namespace raystack::slave {

BlockWalk::BlockWalk(const store::OctreeView& octree, std::span<const store::BlockEntry> blocks)
    : nodes_(octree.nodes()), node_bounds_(octree.bounds()), blocks_(blocks),
      magnitude_(octree.magnitude()), parent_(octree.nodes().size(), 0) {
  const Bounds3f r = octree.root_cell();
  root_ = {{r.lower.x, r.lower.y, r.lower.z}, {r.upper.x, r.upper.y, r.upper.z}};
  // The store reader has checked the tree (children in range, one parent each, bounded depth).
  for (uint32_t n = 0; n < nodes_.size(); ++n)
    if (nodes_[n].kind == store::kOctreeInner)
      for (uint32_t c = 0; c < 8; ++c) parent_[nodes_[n].first + c] = n;
  // Cells from the root down, with the arithmetic of Descend (and store::ChildCell), so Next
  // resumes on exactly the cells a walk from the root would compute.
  cells_.assign(nodes_.size(), Cell{});
  if (nodes_.empty()) return;
  cells_[0] = root_;
  std::vector<uint32_t> todo = {0};
  while (!todo.empty()) {
    const uint32_t n = todo.back();
    todo.pop_back();
    if (nodes_[n].kind != store::kOctreeInner) continue;
    const Cell p = cells_[n];
    for (uint32_t i = 0; i < 8; ++i) {
      const uint32_t c = nodes_[n].first + i;
      for (int a = 0; a < 3; ++a) {
        const float mid = (p.lower[a] + p.upper[a]) * 0.5f;
        const bool upper_half = (i >> a) & 1;
        cells_[c].lower[a] = upper_half ? mid : p.lower[a];
        cells_[c].upper[a] = upper_half ? p.upper[a] : mid;
      }
      todo.push_back(c);
    }
  }
}

}  // namespace raystack::slave
