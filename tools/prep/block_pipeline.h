#pragma once
// Encodes blocks on worker threads and writes them in block-id order. The converter's
// subdivision runs on one thread and submits leaves as it finds them (in Morton order);
// encoding (vertex dedup, BVH build, shuffle, lz4) is the costly part and runs in parallel.
// Submit() waits when too many blocks are in flight, which bounds memory.

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <mutex>
#include <span>
#include <thread>
#include <vector>

#include "common/base/status.h"
#include "common/store/block_encoder.h"
#include "common/store/store_writer.h"

namespace raystack::prep {

struct LeafJob {
  // The bucket's triangles; they must outlive the job (the builder drains before freeing).
  std::span<const store::PackedTriangle> triangles;
  std::span<const store::TriangleAttributes> attributes;
  std::vector<uint32_t> refs;
  std::vector<Bounds3f> ref_bounds;
  Bounds3f cell;
  uint32_t block_id = 0;
  uint32_t octree_leaf = 0;
};

struct PipelineStats {
  uint64_t raw_bytes = 0, stored_bytes = 0, references = 0, vertices = 0, blocks = 0;
  uint32_t largest_raw_bytes = 0;
};

class BlockPipeline {
 public:
  BlockPipeline(int threads, store::StoreWriter* writer, bool shuffle,
                BvhBuildOptions bvh = {});
  ~BlockPipeline();  // stops the workers (after Drain, or abandoning on error)

  void Submit(LeafJob job);
  // Waits until every submitted block is written; returns the first error, if any.
  Status Drain();
  PipelineStats stats() const;

 private:
  void Work();

  store::StoreWriter* writer_;
  bool shuffle_;
  BvhBuildOptions bvh_;
  std::vector<std::thread> workers_;
  mutable std::mutex mutex_;
  std::condition_variable work_ready_, space_ready_, drained_;
  std::deque<LeafJob> queue_;
  std::map<uint32_t, store::EncodedBlock> done_;  // encoded, waiting for their turn
  uint32_t next_to_write_ = 0, submitted_ = 0;
  size_t in_flight_ = 0, max_in_flight_;
  bool stopping_ = false;
  Status error_;
  PipelineStats stats_;
};

}  // namespace raystack::prep
