#include "common/store/store_bvh.h"

#include <limits>

namespace raystack::store {

StoreBvh::StoreBvh(std::span<const BlockView> blocks, int threads) {
  // Each source triangle once: its copy in the lowest block id.
  std::vector<Vec3f> vertices;
  std::vector<uint32_t> ids;
  std::vector<TriangleOrigin> origins;
  std::vector<bool> seen;
  for (const BlockView& b : blocks) {
    for (uint32_t t = 0; t < b.triangle_count(); ++t) {
      const uint32_t id = b.TriangleId(t);
      if (id >= seen.size()) seen.resize(size_t{id} + 1, false);
      if (seen[id]) continue;
      seen[id] = true;
      Vec3f p[3];
      b.TriangleVertices(t, &p[0], &p[1], &p[2]);
      vertices.insert(vertices.end(), p, p + 3);
      ids.push_back(id);
      origins.push_back({b.id(), t});
    }
  }
  bvh_ = WideBvh(vertices, ids, origins, threads);
}

Hit StoreBvh::Intersect(const Ray& ray) const {
  Hit hit;
  hit.t = ray.tmax;
  bvh_.Intersect(ray, &hit);
  if (!hit.Valid()) hit.t = std::numeric_limits<float>::infinity();
  return hit;
}

}  // namespace raystack::store
