#pragma once
// Encodes blocks on worker threads and writes them in submission order. The converter's
// subdivision runs on one thread and submits leaves as it finds them (in Morton order);
// encoding (vertex dedup, BVH build, shuffle, lz4) is the costly part and runs in parallel.
// Submit() waits when too many leaves are in flight, which bounds memory.
//
// The cap on a block's size is enforced here, where the real size is known: a leaf whose
// block comes out larger than the cap is split in two (by the median of its triangles along
// their widest axis) until every part fits. Block ids are therefore given at write time;
// the builder learns each leaf's block range from LeafBlocks() after Drain().

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <span>
#include <thread>
#include <vector>

#include "common/base/status.h"
#include "common/store/block_encoder.h"
#include "common/store/store_writer.h"

namespace raystack::prep {

struct LeafJob {
  // The bucket's triangles, kept alive by keep_alive while the job is queued or encoding.
  std::span<const store::PackedTriangle> triangles;
  std::span<const store::TriangleAttributes> attributes;
  std::shared_ptr<const void> keep_alive;  // owns what the spans point into
  std::vector<uint32_t> refs;
  std::vector<Bounds3f> ref_bounds;
  Bounds3f cell;
  uint32_t octree_leaf = 0;
};

struct PipelineStats {
  uint64_t raw_bytes = 0, stored_bytes = 0, references = 0, vertices = 0, blocks = 0;
  uint64_t cap_splits = 0;  // blocks split because they came out above the cap
  uint32_t largest_raw_bytes = 0;
};

// Blocks [first, first + count) belong to an octree leaf.
struct LeafBlocks {
  uint32_t first = 0, count = 0;
};

class BlockPipeline {
 public:
  BlockPipeline(int threads, store::StoreWriter* writer, bool shuffle, uint32_t max_block_bytes,
                BvhBuildOptions bvh = {});
  ~BlockPipeline();  // stops the workers (after Drain, or abandoning on error)

  void Submit(LeafJob job);
  // Waits until `ready()` holds; it is checked under the pipeline's lock each time a leaf is
  // written (and a job drops what it kept alive before that).
  void WaitUntil(const std::function<bool()>& ready);
  // Waits until every submitted leaf is written; returns the first error, if any.
  Status Drain();
  PipelineStats stats() const;
  // Block ranges of every leaf written so far (valid after Drain).
  const std::map<uint32_t, LeafBlocks>& leaf_blocks() const { return leaf_blocks_; }

 private:
  struct Encoded {
    uint32_t octree_leaf = 0;
    std::vector<store::EncodedBlock> blocks;
  };
  void Work();
  void Encode(const LeafJob& job, std::span<const uint32_t> refs, std::span<const Bounds3f> bounds,
              store::BlockEncoder* encoder, Encoded* out, uint64_t* splits);

  store::StoreWriter* writer_;
  bool shuffle_;
  uint32_t max_block_bytes_;
  BvhBuildOptions bvh_;
  std::vector<std::thread> workers_;
  mutable std::mutex mutex_;
  std::condition_variable work_ready_, space_ready_, drained_;
  std::deque<std::pair<uint64_t, LeafJob>> queue_;  // (sequence, job)
  std::map<uint64_t, Encoded> done_;                // encoded, waiting for their turn
  uint64_t next_to_write_ = 0, submitted_ = 0;
  uint32_t next_block_id_ = 0;
  size_t in_flight_ = 0, max_in_flight_;
  bool stopping_ = false;
  Status error_;
  PipelineStats stats_;
  std::map<uint32_t, LeafBlocks> leaf_blocks_;
};

}  // namespace raystack::prep
