#include "common/store/store_bvh.h"

#include <limits>

#include "common/base/populate.h"

namespace raystack::store {

StoreBvh::StoreBvh(std::span<const BlockView> blocks, int threads) {
  // Each source triangle once: `fn(block, t)` for its copy in the lowest block id.
  auto for_each_first_copy = [&](auto&& fn) {
    std::vector<bool> seen;
    for (const BlockView& b : blocks) {
      for (uint32_t t = 0; t < b.triangle_count(); ++t) {
        const uint32_t id = b.TriangleId(t);
        if (id >= seen.size()) seen.resize(size_t{id} + 1, false);
        if (seen[id]) continue;
        seen[id] = true;
        fn(b, t);
      }
    }
  };
  // Counted first, so the arrays are made once at their size and mapped in one call
  // (ReserveForWrite): grown by doubling, they were copied a dozen times, each time into
  // memory new to the process.
  size_t count = 0;
  for_each_first_copy([&](const BlockView&, uint32_t) { ++count; });
  std::vector<Vec3f> vertices;
  std::vector<uint32_t> ids;
  std::vector<TriangleOrigin> origins;
  ReserveForWrite(&vertices, 3 * count);
  ReserveForWrite(&ids, count);
  ReserveForWrite(&origins, count);
  for_each_first_copy([&](const BlockView& b, uint32_t t) {
    Vec3f p[3];
    b.TriangleVertices(t, &p[0], &p[1], &p[2]);
    vertices.insert(vertices.end(), p, p + 3);
    ids.push_back(b.TriangleId(t));
    origins.push_back({b.id(), t});
  });
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
