#include "slave/block_walk.h"

namespace raystack::slave {

BlockWalk::BlockWalk(const store::OctreeView& octree, std::span<const store::BlockEntry> blocks)
    : nodes_(octree.nodes()), node_bounds_(octree.bounds()), blocks_(blocks), parent_(octree.nodes().size(), 0) {
  const Bounds3f r = octree.root_cell();
  root_ = {{r.lower.x, r.lower.y, r.lower.z}, {r.upper.x, r.upper.y, r.upper.z}};
  // The store reader has checked the tree (children in range, one parent each, bounded depth).
  for (uint32_t n = 0; n < nodes_.size(); ++n)
    if (nodes_[n].kind == store::kOctreeInner)
      for (uint32_t c = 0; c < 8; ++c) parent_[nodes_[n].first + c] = n;
}

}  // namespace raystack::slave
