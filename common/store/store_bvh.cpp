#include "common/store/store_bvh.h"

#include <limits>

namespace raystack::store {
namespace {

// The triangles of `blocks`, each source triangle once (its copy in the lowest block id).
void UniqueTriangles(std::span<const BlockView> blocks, std::vector<Vec3f>* vertices,
                     std::vector<uint32_t>* ids, std::vector<uint32_t>* block_of,
                     std::vector<uint32_t>* local_of) {
  std::vector<bool> seen;
  for (const BlockView& b : blocks) {
    for (uint32_t t = 0; t < b.triangle_count(); ++t) {
      const uint32_t id = b.TriangleId(t);
      if (id >= seen.size()) seen.resize(size_t{id} + 1, false);
      if (seen[id]) continue;
      seen[id] = true;
      Vec3f p[3];
      b.TriangleVertices(t, &p[0], &p[1], &p[2]);
      vertices->insert(vertices->end(), p, p + 3);
      ids->push_back(id);
      block_of->push_back(b.id());
      local_of->push_back(t);
    }
  }
}

}  // namespace

StoreBvh::StoreBvh(std::span<const BlockView> blocks) {
  std::vector<Vec3f> vertices;
  std::vector<uint32_t> ids, block_of, local_of;
  UniqueTriangles(blocks, &vertices, &ids, &block_of, &local_of);
  copies_.resize(ids.size());
  for (size_t i = 0; i < ids.size(); ++i) copies_[i] = {block_of[i], local_of[i]};
  bvh_ = Bvh4(vertices, ids);
}

bool StoreBvh::Intersect(const Ray& ray, Hit* hit) const {
  if (!bvh_.Intersect(ray, hit)) return false;
  const Copy& c = copies_[hit->local_triangle];
  hit->block_id = c.block;
  hit->local_triangle = c.local;
  return true;
}

Hit StoreBvh::Intersect(const Ray& ray) const {
  Hit hit;
  hit.t = ray.tmax;
  Intersect(ray, &hit);
  if (!hit.Valid()) hit.t = std::numeric_limits<float>::infinity();
  return hit;
}

}  // namespace raystack::store
