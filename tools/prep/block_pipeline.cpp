#include "tools/prep/block_pipeline.h"

#include <algorithm>
#include <numeric>

#include "common/store/block_codec.h"

namespace raystack::prep {

BlockPipeline::BlockPipeline(int threads, store::StoreWriter* writer, bool shuffle,
                             uint32_t max_block_bytes, BvhBuildOptions bvh)
    : writer_(writer), shuffle_(shuffle), max_block_bytes_(max_block_bytes), bvh_(bvh),
      max_in_flight_(static_cast<size_t>(64 * std::max(threads, 1))) {
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
  queue_.emplace_back(submitted_++, std::move(job));
  work_ready_.notify_one();
}

void BlockPipeline::WaitUntil(const std::function<bool()>& ready) {
  std::unique_lock<std::mutex> lock(mutex_);
  space_ready_.wait(lock, [&] { return ready() || !error_.ok(); });
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

void BlockPipeline::Encode(const LeafJob& job, std::span<const uint32_t> refs,
                           std::span<const Bounds3f> bounds, store::BlockEncoder* encoder,
                           Encoded* out, uint64_t* splits) {
  store::EncodeInput input;
  input.triangles = job.triangles;
  input.attributes = job.attributes;
  input.refs = refs;
  input.ref_bounds = bounds;
  input.cell = job.cell;
  std::vector<uint8_t> raw;
  encoder->Encode(input, &raw);
  if (raw.size() > max_block_bytes_ && refs.size() > 1) {
    // Too big: halve it at the median of the triangles along their widest axis.
    ++*splits;
    Bounds3f centers;
    for (const Bounds3f& b : bounds) centers.Extend(b.Center());
    const int axis = centers.MaxAxis();
    std::vector<uint32_t> order(refs.size());
    std::iota(order.begin(), order.end(), 0u);
    const size_t half = order.size() / 2;
    std::nth_element(order.begin(), order.begin() + static_cast<long>(half), order.end(),
                     [&](uint32_t a, uint32_t b) {
                       return bounds[a].Center()[axis] < bounds[b].Center()[axis] ||
                              (bounds[a].Center()[axis] == bounds[b].Center()[axis] && a < b);
                     });
    for (int part = 0; part < 2; ++part) {
      const size_t begin = part ? half : 0, end = part ? order.size() : half;
      std::vector<uint32_t> sub_refs;
      std::vector<Bounds3f> sub_bounds;
      for (size_t i = begin; i < end; ++i) {
        sub_refs.push_back(refs[order[i]]);
        sub_bounds.push_back(bounds[order[i]]);
      }
      Encode(job, sub_refs, sub_bounds, encoder, out, splits);
    }
    return;
  }
  store::EncodedBlock block;
  block.raw_bytes = static_cast<uint32_t>(raw.size());
  block.triangles = static_cast<uint32_t>(refs.size());
  block.octree_leaf = job.octree_leaf;
  block.cell = job.cell;
  block.bounds = encoder->bounds();  // this block's: the split branch above returned
  store::EncodeBlock(raw, &block.stored, shuffle_);
  out->blocks.push_back(std::move(block));
}

void BlockPipeline::Work() {
  store::BlockEncoder encoder(bvh_);
  for (;;) {
    uint64_t sequence;
    LeafJob job;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      work_ready_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
      if (queue_.empty()) return;
      sequence = queue_.front().first;
      job = std::move(queue_.front().second);
      queue_.pop_front();
    }
    Encoded encoded;
    encoded.octree_leaf = job.octree_leaf;
    uint64_t splits = 0;
    Encode(job, job.refs, job.ref_bounds, &encoder, &encoded, &splits);
    job = LeafJob{};  // lets go of its bucket before WaitUntil's callers are woken

    std::lock_guard<std::mutex> lock(mutex_);
    stats_.cap_splits += splits;
    done_.emplace(sequence, std::move(encoded));
    // Whoever completes the next leaf in order writes every leaf that is now ready.
    while (error_.ok() && !done_.empty() && done_.begin()->first == next_to_write_) {
      Encoded& e = done_.begin()->second;
      LeafBlocks& range = leaf_blocks_[e.octree_leaf];
      if (range.count == 0) range.first = next_block_id_;
      for (store::EncodedBlock& block : e.blocks) {
        block.id = next_block_id_++;
        ++range.count;
        Status s = writer_->Add(block);
        if (!s.ok()) error_ = s;
        stats_.raw_bytes += block.raw_bytes;
        stats_.stored_bytes += block.stored.size();
        stats_.references += block.triangles;
        stats_.largest_raw_bytes = std::max(stats_.largest_raw_bytes, block.raw_bytes);
        ++stats_.blocks;
      }
      done_.erase(done_.begin());
      ++next_to_write_;
      --in_flight_;
    }
    space_ready_.notify_all();
    if (in_flight_ == 0 || !error_.ok()) drained_.notify_all();
  }
}

}  // namespace raystack::prep
