#include "common/store/block_view.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <iterator>
#include <limits>
#include <vector>

#include "common/base/check.h"
#include "common/base/log.h"
#include "common/store/block_layout.h"

namespace raystack::store {
namespace {

Status Bad(uint32_t block_id, const std::string& what) {
  return Status::Error(StrFormat("block %u is malformed: ", block_id) + what);
}

// The traversal stack holds at most this many pending nodes; Parse rejects deeper trees.
constexpr int kMaxBvhDepth = 64;

// Checks that nodes form one binary tree in depth-first layout, every node reached once, no
// deeper than the traversal stack, and leaves cover valid triangle ranges.
Status CheckBvh(std::span<const BvhNode> nodes, uint32_t triangle_count, uint32_t block_id) {
  if (nodes.empty()) {
    return triangle_count == 0 ? OkStatus() : Bad(block_id, "triangles but no BVH nodes");
  }
  // Items are pushed only from nodes within the depth limit, and each level leaves at most
  // one sibling pending, so a fixed stack holds them (no allocation per block load).
  struct Item { uint32_t node; int depth; };
  Item stack[2 * kMaxBvhDepth + 2];
  int top = 0;
  stack[top++] = {0, 1};
  uint32_t visited = 0;
  uint64_t leaf_triangles = 0;
  while (top > 0) {
    Item item = stack[--top];
    if (item.node >= nodes.size()) return Bad(block_id, "BVH child index out of range");
    if (item.depth > kMaxBvhDepth) return Bad(block_id, "BVH deeper than 64 levels");
    if (++visited > nodes.size()) return Bad(block_id, "BVH is not a tree");
    const BvhNode& n = nodes[item.node];
    for (int a = 0; a < 3; ++a) {
      if (std::isnan(n.lower[a]) || std::isnan(n.upper[a]))
        return Bad(block_id, "NaN in BVH bounds");
      if (n.lower[a] > n.upper[a]) return Bad(block_id, "an inverted BVH box");
    }
    if (n.count > 0) {
      if (uint64_t{n.offset} + n.count > triangle_count)
        return Bad(block_id, "BVH leaf points past the triangles");
      leaf_triangles += n.count;
    } else {
      if (n.offset <= item.node + 1 || n.axis > 2)
        return Bad(block_id, "BVH inner node with a bad child or axis");
      // A box is the union of its children's: one outside it hides their triangles from the
      // walk (a forged block, checksums made again: a hostile-input review).
      for (const uint32_t c : {item.node + 1, n.offset}) {
        if (c >= nodes.size()) return Bad(block_id, "BVH child index out of range");
        for (int a = 0; a < 3; ++a)
          if (nodes[c].lower[a] < n.lower[a] || nodes[c].upper[a] > n.upper[a])
            return Bad(block_id, "a BVH box outside its parent's");
      }
      CHECK(top + 2 <= static_cast<int>(std::size(stack)));
      stack[top++] = {n.offset, item.depth + 1};
      stack[top++] = {item.node + 1, item.depth + 1};
    }
  }
  if (visited != nodes.size()) return Bad(block_id, "BVH has unreachable nodes");
  if (leaf_triangles != triangle_count)
    return Bad(block_id, "BVH leaves do not cover each triangle once");
  return OkStatus();
}

}  // namespace

Expected<BlockView> BlockView::Parse(const uint8_t* raw, uint64_t size, uint32_t block_id) {
  if (reinterpret_cast<uintptr_t>(raw) % 16 != 0) return Bad(block_id, "buffer not aligned");
  if (size < sizeof(BlockHeader)) return Bad(block_id, "shorter than its header");
  BlockView v;
  v.id_ = block_id;
  v.header_ = reinterpret_cast<const BlockHeader*>(raw);
  const BlockHeader& h = *v.header_;
  if (h.magic != kBlockMagic) return Bad(block_id, "bad magic");
  if (h.version != kFormatVersion)
    return Bad(block_id, StrFormat("version %u, expected %u", h.version, kFormatVersion));
  if (h.flags & ~uint16_t{0xf}) return Bad(block_id, "unknown flags");
  const BlockLayout layout = BlockLayout::For(h);
  if (layout.total != size)
    return Bad(block_id, StrFormat("size %llu does not match its counts (%llu)",
                                   static_cast<unsigned long long>(size),
                                   static_cast<unsigned long long>(layout.total)));
  if (!(h.flags & kBlockIndices32) && h.vertex_count > 65536)
    return Bad(block_id, "16-bit indices with more than 65536 vertices");

  v.bytes_ = size;
  v.nodes_ = reinterpret_cast<const BvhNode*>(raw + layout.nodes);
  const auto* pos = reinterpret_cast<const float*>(raw + layout.positions);
  v.x_ = pos;
  v.y_ = pos + h.vertex_count;
  v.z_ = pos + 2 * uint64_t{h.vertex_count};
  if (h.flags & kBlockIndices32)
    v.indices32_ = reinterpret_cast<const uint32_t*>(raw + layout.indices);
  else
    v.indices16_ = reinterpret_cast<const uint16_t*>(raw + layout.indices);
  v.ids_ = reinterpret_cast<const uint32_t*>(raw + layout.triangle_ids);
  if (h.flags & kBlockPerTriangleMaterial)
    v.materials_ = reinterpret_cast<const uint16_t*>(raw + layout.materials);
  if (h.flags & kBlockNormals) {
    const auto* n = reinterpret_cast<const float*>(raw + layout.normals);
    v.nx_ = n;
    v.ny_ = n + h.vertex_count;
    v.nz_ = n + 2 * uint64_t{h.vertex_count};
  }

  // Reductions without early exits, so the compiler vectorises them: every block is checked
  // on every load, and a valid block (the common case) is read to the end anyway.
  const uint64_t index_count = 3 * uint64_t{h.triangle_count};
  uint32_t max_index = 0;
  if (v.indices32_) {
    for (uint64_t i = 0; i < index_count; ++i)
      max_index = v.indices32_[i] > max_index ? v.indices32_[i] : max_index;
  } else {
    for (uint64_t i = 0; i < index_count; ++i)
      max_index = v.indices16_[i] > max_index ? v.indices16_[i] : max_index;
  }
  if (index_count > 0 && max_index >= h.vertex_count)
    return Bad(block_id, "vertex index out of range");
  // A float is NaN or infinite when its exponent bits are all ones; adding one to the
  // exponent field carries into the sign bit exactly then. Integer ORs vectorise (a float sum
  // would not: its order is fixed). The same pass finds the largest |coordinate| (the box
  // tests' margin): finite floats without their sign order as their bits do.
  uint32_t carry = 0, largest = 0;
  for (uint64_t i = 0; i < 3 * uint64_t{h.vertex_count}; ++i) {
    uint32_t bits;
    std::memcpy(&bits, &pos[i], sizeof bits);
    carry |= (bits & 0x7f800000u) + 0x00800000u;
    largest = std::max(largest, bits & 0x7fffffffu);
  }
  if (carry & 0x80000000u) return Bad(block_id, "non-finite vertex coordinate");
  std::memcpy(&v.magnitude_, &largest, sizeof largest);
  RAYSTACK_RETURN_IF_ERROR(CheckBvh(v.nodes(), h.triangle_count, block_id));
  return v;
}

uint32_t BlockView::LargestTriangleId() const {
  uint32_t largest = 0;
  for (uint32_t t = 0; t < header_->triangle_count; ++t) largest = ids_[t] > largest ? ids_[t] : largest;
  return largest;
}

Bounds3f BlockView::VertexBounds() const {
  Bounds3f b;
  const float* axes[3] = {x_, y_, z_};
  for (int a = 0; a < 3; ++a) {
    // Finite (Parse checked); in this form (not std::min) the loop takes vector min/max.
    float lo = b.lower[a], hi = b.upper[a];
    for (uint32_t i = 0; i < header_->vertex_count; ++i) {
      const float v = axes[a][i];
      lo = v < lo ? v : lo;
      hi = v > hi ? v : hi;
    }
    b.lower[a] = lo;
    b.upper[a] = hi;
  }
  return b;
}

BoxBounds BlockView::bounds() const {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  BoxBounds b{{kInf, kInf, kInf}, {-kInf, -kInf, -kInf}};  // empty, as the encoder's
  if (header_->node_count > 0) {
    std::memcpy(b.lower, nodes_[0].lower, sizeof b.lower);
    std::memcpy(b.upper, nodes_[0].upper, sizeof b.upper);
  }
  return b;
}

Bounds3f BlockView::cell() const {
  const BlockHeader& h = *header_;
  return {{h.cell_lower[0], h.cell_lower[1], h.cell_lower[2]},
          {h.cell_upper[0], h.cell_upper[1], h.cell_upper[2]}};
}

bool BlockView::Intersect(const Ray& ray, Hit* hit) const {
  const RayTriangleSetup setup(ray);
  bool found = false;
  // Hits equal to the best t must still be tested (the smaller id wins a tie), so the
  // triangle test's open upper bound is one float above it.
  float tmax = NextUp(hit->t);
  TraverseBvh(nodes(), ray, magnitude_, &tmax, [&](uint32_t first, uint32_t count) {
    found |= IntersectLeaf(setup, ray, first, count, &tmax, hit);
    return false;
  });
  return found;
}

bool BlockView::Occluded(const Ray& ray) const {
  const RayTriangleSetup setup(ray);
  float tmax = ray.tmax;
  bool occluded = false;
  TraverseBvh(nodes(), ray, magnitude_, &tmax, [&](uint32_t first, uint32_t count) {
    occluded = OccludedLeaf(setup, ray, first, count);
    return occluded;
  });
  return occluded;
}

}  // namespace raystack::store
