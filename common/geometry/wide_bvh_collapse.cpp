#include "common/geometry/wide_bvh_collapse.h"

#include <limits>

#include "common/base/check.h"

namespace raystack {

void WideCollapse::Plan(std::span<const BvhNode> nodes, uint32_t root, int width, float node_cost,
                        float primitive_cost) {
  CHECK(root < nodes.size() && width >= 2 && width <= kMaxWidth);
  nodes_ = nodes;
  root_ = root;
  width_ = width;
  // Depth first: the subtree ends after its last leaf, reached through the second children.
  uint32_t last = root;
  while (nodes[last].count == 0) last = nodes[last].offset;
  entries_.assign(last + 1 - root, Entry{});
  constexpr float kInf = std::numeric_limits<float>::infinity();
  // Children come after their parent: each node is planned from its children's plans.
  for (uint32_t n = last + 1; n-- > root;) {
    const BvhNode& b = nodes[n];
    Entry& e = entries_[n - root];
    const float area = NodeBounds(b).HalfArea();
    if (b.count != 0) {
      e.first = b.offset;
      e.count = b.count;
      e.as_leaf = true;
      e.as_node = kInf;
      e.cost.fill(area * primitive_cost * static_cast<float>(b.count));
      e.split.fill(0);
      continue;
    }
    const Entry& l = at(n + 1);
    const Entry& r = at(b.offset);
    DCHECK(r.first == l.first + l.count);  // a subtree's primitives are one run
    e.first = l.first;
    e.count = l.count + r.count;
    // Comparisons with an infinite or NaN cost (the areas of boxes near the float range's end
    // overflow) fail, and leave these valid choices in place: one child from the first subtree,
    // and each node one child (split 0).
    e.as_node = kInf;
    e.node_split = 1;
    for (int k = 1; k < width; ++k) {
      const float c = l.cost[k - 1] + r.cost[width - k - 1];
      if (c < e.as_node) e.as_node = c, e.node_split = static_cast<uint8_t>(k);
    }
    e.as_node += area * node_cost;
    float single = e.as_node;
    if (e.count <= kMaxLeaf) {
      const float leaf = area * primitive_cost * static_cast<float>(e.count);
      if (leaf <= single) single = leaf, e.as_leaf = true;
    }
    e.cost.fill(single);
    e.split.fill(0);
    for (int j = 2; j <= width; ++j) {
      for (int k = 1; k < j; ++k) {
        const float c = l.cost[k - 1] + r.cost[j - k - 1];
        if (c < e.cost[j - 1]) e.cost[j - 1] = c, e.split[j - 1] = static_cast<uint8_t>(k);
      }
    }
  }
}

int WideCollapse::Children(uint32_t n, uint32_t out[kMaxWidth]) const {
  const BvhNode& b = nodes_[n];
  CHECK(b.count == 0);
  const int k = at(n).node_split;
  int size = 0;
  Distribute(n + 1, k, out, &size);
  Distribute(b.offset, width_ - k, out, &size);
  return size;
}

void WideCollapse::Distribute(uint32_t n, int j, uint32_t* out, int* size) const {
  const int k = at(n).split[j - 1];
  if (k == 0) {
    out[(*size)++] = n;
    return;
  }
  Distribute(n + 1, k, out, size);
  Distribute(nodes_[n].offset, j - k, out, size);
}

}  // namespace raystack
