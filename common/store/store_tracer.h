#pragma once
// Synchronous closest-hit and any-hit queries against a whole store: walks the level-1 octree
// front to back and intersects each crossed leaf's blocks, loading them on first use and
// keeping them. Unbounded memory: this is the reference path for tests and tools (and the
// in-core baseline), not the renderer's ray stack. Not thread-safe, except that once LoadAll()
// has succeeded, Intersect and Occluded only read and may run on several threads at once.

#include <cstdint>
#include <memory>
#include <vector>

#include "common/base/status.h"
#include "common/geometry/ray.h"
#include "common/store/store_reader.h"

namespace raystack::store {

class StoreTracer {
 public:
  explicit StoreTracer(const StoreReader& store);
  ~StoreTracer();

  // Closest hit in (ray.tmin, ray.tmax); an invalid Hit when the ray hits nothing.
  Expected<Hit> Intersect(const Ray& ray);
  // True when anything lies in (ray.tmin, ray.tmax).
  Expected<bool> Occluded(const Ray& ray);
  // Loads every block now (for in-core use).
  Status LoadAll();

  uint64_t blocks_loaded() const { return blocks_loaded_; }

 private:
  struct Loaded;
  Expected<const BlockView*> Block(uint32_t id);
  // Calls per_block(view) for each block of each leaf the ray crosses, nearest first, until
  // it returns false; a block that fails to load ends the walk with its error.
  template <typename PerBlock>
  Status VisitBlocks(const Ray& ray, float* tmax, PerBlock&& per_block);

  const StoreReader& store_;
  std::vector<std::unique_ptr<Loaded>> blocks_;  // by block id; null until loaded
  std::vector<uint8_t> stored_;
  AlignedBuffer scratch_;
  uint64_t blocks_loaded_ = 0;
};

}  // namespace raystack::store
