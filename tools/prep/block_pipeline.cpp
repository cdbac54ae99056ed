#include "tools/prep/block_pipeline.h"

#include <algorithm>

#include "common/store/block_codec.h"

namespace raystack::prep {

BlockPipeline::BlockPipeline(int threads, store::StoreWriter* writer, bool shuffle,
                             BvhBuildOptions bvh)
    : writer_(writer), shuffle_(shuffle), bvh_(bvh),
      max_in_flight_(static_cast<size_t>(16 * std::max(threads, 1))) {
  for (int i = 0; i < std::max(threads, 1); ++i) workers_.emplace_back([this] { Work(); });
}

BlockPipeline::~BlockPipeline() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  work_ready_.notify_all();
  for (std::thread& t : workers_) t.join();
}

void BlockPipeline::Submit(LeafJob job) {
  std::unique_lock<std::mutex> lock(mutex_);
  space_ready_.wait(lock, [&] { return in_flight_ < max_in_flight_ || !error_.ok(); });
  if (!error_.ok()) return;  // reported by Drain
  ++in_flight_;
  ++submitted_;
  queue_.push_back(std::move(job));
  work_ready_.notify_one();
}

Status BlockPipeline::Drain() {
  std::unique_lock<std::mutex> lock(mutex_);
  drained_.wait(lock, [&] { return in_flight_ == 0 || !error_.ok(); });
  return error_;
}

PipelineStats BlockPipeline::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

void BlockPipeline::Work() {
  store::BlockEncoder encoder(bvh_);
  std::vector<uint8_t> raw;
  for (;;) {
    LeafJob job;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      work_ready_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
      if (queue_.empty()) return;
      job = std::move(queue_.front());
      queue_.pop_front();
    }
    store::EncodeInput input;
    input.triangles = job.triangles;
    input.attributes = job.attributes;
    input.refs = job.refs;
    input.ref_bounds = job.ref_bounds;
    input.cell = job.cell;
    input.block_id = job.block_id;
    const uint32_t vertices = encoder.Encode(input, &raw);
    store::EncodedBlock block;
    block.id = job.block_id;
    block.raw_bytes = static_cast<uint32_t>(raw.size());
    block.triangles = static_cast<uint32_t>(job.refs.size());
    block.octree_leaf = job.octree_leaf;
    block.cell = job.cell;
    store::EncodeBlock(raw, &block.stored, shuffle_);

    std::lock_guard<std::mutex> lock(mutex_);
    stats_.raw_bytes += block.raw_bytes;
    stats_.stored_bytes += block.stored.size();
    stats_.references += block.triangles;
    stats_.vertices += vertices;
    stats_.largest_raw_bytes = std::max(stats_.largest_raw_bytes, block.raw_bytes);
    ++stats_.blocks;
    done_.emplace(block.id, std::move(block));
    // Whoever completes the next block in order writes every block that is now ready.
    while (error_.ok() && !done_.empty() && done_.begin()->first == next_to_write_) {
      Status s = writer_->Add(done_.begin()->second);
      if (!s.ok()) error_ = s;
      done_.erase(done_.begin());
      ++next_to_write_;
      --in_flight_;
    }
    space_ready_.notify_all();
    if (in_flight_ == 0 || !error_.ok()) drained_.notify_all();
  }
}

}  // namespace raystack::prep
