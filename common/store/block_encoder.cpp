#include "common/store/block_encoder.h"

#include <cstring>

#include "common/base/check.h"
#include "common/store/block_layout.h"
#include "common/store/format.h"

namespace raystack::store {
namespace {

// A vertex is its position plus, when the block has attributes, its normal and uv: two
// corners are one vertex only if all of these are bit-identical.
struct VertexKey {
  float v[8] = {};
  int floats = 3;
  bool operator==(const VertexKey& o) const {
    return std::memcmp(v, o.v, sizeof(float) * static_cast<size_t>(floats)) == 0;
  }
};

VertexKey KeyOf(const EncodeInput& in, uint32_t tri, int corner, bool attributes) {
  VertexKey k;
  const Vec3f& p = in.triangles[tri].p[corner];
  k.v[0] = p.x;
  k.v[1] = p.y;
  k.v[2] = p.z;
  if (attributes) {
    const TriangleAttributes& a = in.attributes[tri];
    k.v[3] = a.n[corner].x;
    k.v[4] = a.n[corner].y;
    k.v[5] = a.n[corner].z;
    k.v[6] = a.uv[corner][0];
    k.v[7] = a.uv[corner][1];
    k.floats = 8;
  }
  return k;
}

// A table slot for a key. Only the probe order depends on it, never which index a vertex
// gets (first occurrence in BVH order), so blocks do not change with it. A multiply-xorshift
// of the bits is enough for positions and far cheaper than a general hash call per corner.
uint64_t HashOf(const VertexKey& key) {
  uint32_t bits[8];
  std::memcpy(bits, key.v, sizeof bits);
  uint64_t h = 0x9e3779b97f4a7c15ull;
  for (int i = 0; i < key.floats; ++i) {
    h = (h ^ bits[i]) * 0xff51afd7ed558ccdull;
    h ^= h >> 32;
  }
  return h;
}

template <typename T>
T* At(std::vector<uint8_t>* raw, uint64_t offset) {
  return reinterpret_cast<T*>(raw->data() + offset);
}

}  // namespace

uint32_t BlockEncoder::VertexOf(const EncodeInput& in, uint32_t tri, int corner, bool attributes) {
  const VertexKey key = KeyOf(in, tri, corner, attributes);
  const uint64_t mask = slots_.size() - 1;
  uint64_t h = HashOf(key) & mask;
  for (;; h = (h + 1) & mask) {
    uint32_t slot = slots_[h];
    if (slot == 0) {
      const uint32_t index = static_cast<uint32_t>(vertex_source_.size());
      vertex_source_.push_back(uint64_t{tri} * 3 + static_cast<uint64_t>(corner));
      slots_[h] = index + 1;
      return index;
    }
    const uint64_t source = vertex_source_[slot - 1];
    if (KeyOf(in, static_cast<uint32_t>(source / 3), static_cast<int>(source % 3), attributes) == key)
      return slot - 1;
  }
}

uint32_t BlockEncoder::Encode(const EncodeInput& in, std::vector<uint8_t>* raw) {
  const uint32_t n = static_cast<uint32_t>(in.refs.size());
  CHECK(in.ref_bounds.size() == in.refs.size());

  // BVH over the clipped bounds; `order_` then lists refs in leaf order.
  prims_.resize(n);
  for (uint32_t i = 0; i < n; ++i) prims_[i].bounds = in.ref_bounds[i];
  std::vector<BvhNode> nodes = BuildBvh(prims_, bvh_, &order_);
  bounds_ = Bounds3f{};
  if (!nodes.empty()) {
    bounds_.lower = {nodes[0].lower[0], nodes[0].lower[1], nodes[0].lower[2]};
    bounds_.upper = {nodes[0].upper[0], nodes[0].upper[1], nodes[0].upper[2]};
  }

  // Which optional parts this block needs.
  bool normals = false, uvs = false, per_triangle_material = false;
  const uint32_t first_material = n ? in.triangles[in.refs[0]].material() : kNoMaterial;
  for (uint32_t r : in.refs) {
    const PackedTriangle& t = in.triangles[r];
    normals |= t.has_normals();
    uvs |= t.has_uvs();
    per_triangle_material |= t.material() != first_material;
  }
  const bool attributes = (normals || uvs) && !in.attributes.empty();

  // Deduplicate vertices (in BVH order, so nearby triangles get nearby vertex indices).
  uint64_t capacity = 16;
  while (capacity < 6ull * n) capacity *= 2;
  slots_.assign(capacity, 0);
  vertex_source_.clear();
  corners_.resize(3ull * n);
  for (uint32_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) corners_[3ull * i + c] = VertexOf(in, in.refs[order_[i]], c, attributes);
  const uint32_t v = static_cast<uint32_t>(vertex_source_.size());

  BlockHeader h{};
  h.magic = kBlockMagic;
  h.version = kFormatVersion;
  h.flags = static_cast<uint16_t>((v > 65536 ? kBlockIndices32 : 0) |
                                  (per_triangle_material ? kBlockPerTriangleMaterial : 0) |
                                  (attributes && normals ? kBlockNormals : 0) |
                                  (attributes && uvs ? kBlockUvs : 0));
  h.vertex_count = v;
  h.triangle_count = n;
  h.node_count = static_cast<uint32_t>(nodes.size());
  h.constant_material = per_triangle_material ? kNoMaterial : first_material;
  for (int a = 0; a < 3; ++a) {
    h.cell_lower[a] = in.cell.lower[a];
    h.cell_upper[a] = in.cell.upper[a];
  }
  const BlockLayout l = BlockLayout::For(h);
  raw->assign(l.total, 0);  // zero padding: deterministic bytes, better compression
  std::memcpy(raw->data(), &h, sizeof h);
  if (!nodes.empty()) std::memcpy(raw->data() + l.nodes, nodes.data(), nodes.size() * sizeof(BvhNode));

  float* px = At<float>(raw, l.positions);
  float* nx = At<float>(raw, l.normals);
  float* uu = At<float>(raw, l.uvs);
  for (uint32_t i = 0; i < v; ++i) {
    const auto tri = static_cast<uint32_t>(vertex_source_[i] / 3);
    const int corner = static_cast<int>(vertex_source_[i] % 3);
    const Vec3f& p = in.triangles[tri].p[corner];
    px[i] = p.x;
    px[v + i] = p.y;
    px[2ull * v + i] = p.z;
    if (h.flags & kBlockNormals) {
      const Vec3f& nn = in.attributes[tri].n[corner];
      nx[i] = nn.x;
      nx[v + i] = nn.y;
      nx[2ull * v + i] = nn.z;
    }
    if (h.flags & kBlockUvs) {
      uu[i] = in.attributes[tri].uv[corner][0];
      uu[v + i] = in.attributes[tri].uv[corner][1];
    }
  }
  for (uint64_t k = 0; k < 3ull * n; ++k) {
    if (h.flags & kBlockIndices32)
      At<uint32_t>(raw, l.indices)[k] = corners_[k];
    else
      At<uint16_t>(raw, l.indices)[k] = static_cast<uint16_t>(corners_[k]);
  }
  for (uint32_t i = 0; i < n; ++i) {
    const PackedTriangle& t = in.triangles[in.refs[order_[i]]];
    At<uint32_t>(raw, l.triangle_ids)[i] = t.id;
    if (per_triangle_material)
      At<uint16_t>(raw, l.materials)[i] =
          t.material() == kNoMaterial ? kNoMaterial16 : static_cast<uint16_t>(t.material());
  }
  return v;
}

}  // namespace raystack::store
