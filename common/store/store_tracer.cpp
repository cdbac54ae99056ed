#include "common/store/store_tracer.h"

namespace raystack::store {

struct StoreTracer::Loaded {
  AlignedBuffer raw;
  BlockView view;
};

StoreTracer::StoreTracer(const StoreReader& store)
    : store_(store), blocks_(store.blocks().size()) {}

StoreTracer::~StoreTracer() = default;

Expected<const BlockView*> StoreTracer::Block(uint32_t id) {
  if (!blocks_[id]) {
    auto loaded = std::make_unique<Loaded>();
    Expected<BlockView> view = store_.Load(id, &stored_, &scratch_, &loaded->raw);
    if (!view.ok()) return view.status();
    loaded->view = *view;
    blocks_[id] = std::move(loaded);
    ++blocks_loaded_;
  }
  return &blocks_[id]->view;
}

Status StoreTracer::LoadAll() {
  for (uint32_t id = 0; id < blocks_.size(); ++id) {
    Expected<const BlockView*> b = Block(id);
    if (!b.ok()) return b.status();
  }
  return OkStatus();
}

template <typename PerBlock>
Status StoreTracer::VisitBlocks(const Ray& ray, float* tmax, PerBlock&& per_block) {
  Status error;
  const OctreeView octree = store_.octree();
  const RayBoxSetup setup(ray, octree.magnitude());
  octree.VisitLeaves(ray, setup, tmax, [&](uint32_t, const OctreeNode& leaf, float, float) {
    for (uint32_t b = leaf.first; b < leaf.first + leaf.count; ++b) {
      // Not even loaded when the ray misses its bounds.
      if (!MayHit(setup, BoundsOf(store_.blocks()[b]), ray.tmin, *tmax)) continue;
      Expected<const BlockView*> block = Block(b);
      if (!block.ok()) {
        error = block.status();
        return false;
      }
      if (!per_block(**block)) return false;
    }
    return true;
  });
  return error;
}

Expected<Hit> StoreTracer::Intersect(const Ray& ray) {
  Hit hit;
  hit.t = ray.tmax;
  float tmax = ray.tmax;
  RAYSTACK_RETURN_IF_ERROR(VisitBlocks(ray, &tmax, [&](const BlockView& block) {
    block.Intersect(ray, &hit);
    tmax = hit.t;  // later leaves start beyond the best hit: skip them
    return true;
  }));
  if (!hit.Valid()) hit.t = std::numeric_limits<float>::infinity();
  return hit;
}

Expected<bool> StoreTracer::Occluded(const Ray& ray) {
  bool occluded = false;
  float tmax = ray.tmax;
  RAYSTACK_RETURN_IF_ERROR(VisitBlocks(ray, &tmax, [&](const BlockView& block) {
    occluded = block.Occluded(ray);
    return !occluded;
  }));
  return occluded;
}

}  // namespace raystack::store
