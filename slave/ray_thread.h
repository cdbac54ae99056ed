#pragma once
// One ray thread of a slave: its own ray stack (waiting queues per block), its own sample
// slots, fed with tiles of primary rays. Two drivers over the same per-ray code, so the modes
// differ only in when blocks are read, never in what a ray computes:
// - RunStack: trace whichever ready queue comes first; a ray whose next block is missing
//   waits in that block's queue while the loader reads it (thesis Fig. VI.3);
// - RunSync: trace one ray at a time to the end, reading a missing block on the spot (the
//   thesis's baseline).

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <limits>
#include <mutex>
#include <vector>

#include "common/base/status.h"
#include "common/render/camera.h"
#include "common/render/frame_plan.h"
#include "common/render/sample_result.h"
#include "common/store/store_bvh.h"
#include "common/store/store_reader.h"
#include "slave/block_cache.h"
#include "slave/block_loader.h"
#include "slave/block_source.h"
#include "slave/block_walk.h"
#include "slave/ray_queues.h"
#include "slave/render_stats.h"
#include "slave/sample_slots.h"
#include "slave/shading.h"
#include "slave/primary_approach.h"
#include "slave/tile_source.h"

namespace raystack::slave {

// What every ray thread of one frame shares (all thread-safe or read-only).
struct FrameShared {
  const store::StoreReader* store = nullptr;
  const BlockWalk* walk = nullptr;  // the order in which rays visit blocks
  BlockCache* cache = nullptr;
  BlockLoader* loader = nullptr;  // stack mode only
  BlockSource* source = nullptr;  // sync reads
  const store::StoreBvh* bvh = nullptr;  // bvh mode: rays traced through it, not the blocks
  bool stack = true;              // which driver routes rays
  const Shader* shader = nullptr;
  const render::Camera* camera = nullptr;
  PrimaryApproach approach;  // where a far camera's primary rays start
  TileSource* tiles = nullptr;
  render::SampleSink* sink = nullptr;
  int spp = 1;  // samples of a tile whose sample_end is 0
  uint64_t seed = 1;
  render::PixelOrder pixel_order = render::PixelOrder::kPriority;
  double feed_fraction = 0.1;
  double tile_ahead = 0.0;
  size_t result_batch = 1024;
  // The most samples of a tile a thread feeds at once (RayThread::FeedChunk). In core (every
  // block stays resident) kResidentFeedSamples: a pass of 32 samples over a 32 x 32 tile opened
  // 32,768 samples (4 MB of slots, past the L2 cache), whose slots missed the cache at every
  // ray's end (RayThread::Finish was 14.6% of a path-traced Cornell box; a performance
  // helper's perf). Out of core a tile's samples go in at once, as they did: a block read then
  // serves all of them (chunks of 4,096 loaded 20-55% more blocks with a small cache; found by
  // the day's review).
  static constexpr uint32_t kResidentFeedSamples = 4096;
  static constexpr uint64_t kMostFedShadowRays = uint64_t{1} << 20;
  uint32_t max_feed_samples = std::numeric_limits<uint32_t>::max();

  // The first error ends the frame on every thread.
  std::atomic<bool> abort{false};
  std::mutex error_mu;
  Status error;
  std::vector<class RayThread*> threads;  // woken when the frame fails
  void Fail(const Status& status);
};

// Kept by the engine across frames: its stack, sample slots and buffers keep their memory, so a
// warm frame touches none that is new (each new page is a fault, ~12 us on a VM whose host takes
// freed memory back; a slave's warm frame made ~80 of them here).
class RayThread {
 public:
  // bvh mode: the most shadow rays a thread puts aside (RunSync), so its memory stays bounded
  // whatever the lights: 1 MB of records.
  static constexpr size_t kMaxShadowsAside = size_t{1} << 14;
  static_assert(kMaxShadowsAside * sizeof(RayRecord) == size_t{1} << 20);

  RayThread(uint32_t index, uint32_t block_count);

  // Starts a frame: no rays, no tiles, counters at zero; the memory stays.
  void BeginFrame(FrameShared* shared);

  void RunStack();
  void RunSync();
  // Loader callback: block ready (pinned for this thread) or failed. Thread-safe.
  void Deliver(uint32_t block, const Status& status);
  // Wakes the thread if it waits (abort).
  void Wake();

  const ThreadCounters& counters() const { return counters_; }

 private:
  // A tile's samples are fed in chunks (FeedChunk): an ActiveTile is one chunk.
  struct ActiveTile {
    Tile tile;
    uint32_t total = 0, done = 0;
    uint32_t feed = 0;  // which tile fed it (feed_seq_ then)
  };
  bool NeedFeed() const;
  // Starts the next chunk of the tile being fed, else the next tile's first; false when there
  // is none. `may_wait`: this thread holds no rays, so it may wait for the tile source (its
  // results are sent first, since the master may be waiting for them); otherwise only a tile
  // that is ready is taken.
  bool FeedNextTile(bool may_wait);
  // Feeds the next samples of the tile being fed, at most FrameShared::max_feed_samples.
  void FeedChunk();
  // The index of a new entry of tiles_ holding `chunk` (a finished one's, else a new one).
  uint32_t NewChunk(const ActiveTile& chunk);
  RayRecord PrimaryRay(int x, int y, uint32_t sample, uint32_t slot, uint16_t priority) const;
  // Puts a ray where it goes next: its next block's queue, or finished (stack driver).
  // `from_block`: the block the ray has just been traced through (kInvalidId: none yet).
  void Route(RayRecord& ray, uint32_t from_block);
  // The block `ray` needs after `from_block` (kInvalidId: its first), or kInvalidId: done.
  uint32_t NextBlockOf(const RayRecord& ray, uint32_t from_block) const;
  void Enqueue(const RayRecord& ray, uint32_t block);
  void TraceQueue(uint32_t q);
  void TraceChunk(const store::BlockView& view, uint32_t block, RayRecord* rays, uint32_t count);
  void Finish(const RayRecord& ray);
  void RayDone(uint32_t slot);
  void DrainInbox();
  void FlushResults();
  // Thesis P_ra: once the newest tile is this far along, the tile source may fetch the next.
  void AskAhead();
  // Sync driver pieces.
  void TraceSync(RayRecord ray);
  // bvh mode: the whole ray at once through the one tree (every block is resident).
  void TraceBvh(RayRecord ray);
  // bvh mode: the closest hits of the primary rays just fed (pending_[first ..)), found in
  // packets of neighbouring pixels; each ray is marked kPretraced and finishes when popped.
  void PretraceBvh(size_t first, uint32_t sample_begin, uint32_t sample_end, const Tile& tile);
  // One packet of those rays, pending_[index[0 .. n)], n <= WideBvh::kPacketSize.
  void TracePacket(const size_t* index, int n);
  // bvh mode: records a closer hit the one tree found, from the block that holds the triangle.
  void RecordBvhHit(const Hit& hit, RayRecord* ray);
  // bvh mode: puts a shadow ray of a primary hit aside (RunSync), with its key for TraceShadows.
  void PutAside(const RayRecord& ray);
  // bvh mode: traces the shadow rays put aside in shadows_ (all of them), as packets of rays
  // from neighbouring pixels to one light, and finishes each (a shadow ray has no children).
  void TraceShadows();
  const store::BlockView* AcquireSync(uint32_t block);

  FrameShared* shared_ = nullptr;
  const uint32_t index_;
  RayQueues queues_;
  SampleSlots slots_;
  ThreadCounters counters_;
  // Chunks fed, by local index; a finished chunk's entry is reused (free_chunks_), so a frame of
  // many samples keeps as many entries as it has chunks open at once.
  std::vector<ActiveTile> tiles_;
  uint32_t newest_tile_ = 0;
  uint32_t open_tiles_ = 0;  // fed and not finished
  bool ahead_asked_ = false;  // TileSource::Ahead called for the newest tile
  // Tiles a thread keeps open when all its rays wait. dragon x36 out of core, local disk: 4 -> 8
  // cut the ray threads' idle time 0.24 -> 0.14 s and the run 1.25 -> 1.16 s (medians of 5);
  // 16 loaded more blocks (the cache thrashes) and took 1.43 s.
  static constexpr uint32_t kMaxOpenTiles = 8;
  // ... and only while fewer rays than this wait (64 MB of records): a whitted scene of many
  // lights sends a shadow ray from every hit to each, and 8 such tiles held 839 MB at 1,024
  // lights (the day's review). Far above any other scene's peak (thousands of rays).
  static constexpr uint64_t kMostWaitingToOpenMore = uint64_t{1} << 20;
  // The tile being fed, in chunks of whole samples over all its pixels (at most
  // FrameShared::max_feed_samples, which keeps the feed order): its samples [feed_next_,
  // feed_end_) are still to feed; its chunks are the entries of tiles_ whose `feed` is
  // feed_seq_, and feed_done_ of its feed_total_ samples are done.
  Tile feed_tile_;
  uint32_t feed_next_ = 0, feed_end_ = 0;
  uint32_t feed_seq_ = 0;
  uint64_t feed_total_ = 0, feed_done_ = 0;
  std::vector<uint32_t> free_chunks_;  // entries of tiles_ whose chunk is done, to reuse
  bool tiles_exhausted_ = false;
  std::vector<render::SampleResult> results_;
  uint64_t rays_reported_ = 0;  // rays counted in the batches handed to the sink
  struct FeedPixel {
    uint16_t priority;
    int x, y;
  };
  std::vector<FeedPixel> feed_pixels_;
  std::vector<int32_t> feed_grid_;  // bvh mode: a tile pixel's index in feed_pixels_, or -1
  ShadeOutput shade_;
  std::vector<RayRecord> pending_;  // rays to route (children, primaries): no recursion
  // bvh mode: shadow rays put aside until the rays fed with them are done (TraceShadows), and
  // their order there (PutAside's keys).
  std::vector<RayRecord> shadows_;
  std::vector<uint64_t> shadow_keys_;
  uint32_t aside_ordinal_ = 0;  // the last ray put aside: which of its sample's shadow rays
  std::vector<uint32_t> taken_chunks_;
  // One chunk's rays of one kind for the block's batch calls (TraceChunk), and where each came
  // from.
  Ray batch_rays_[kChunkRays];
  Hit batch_hits_[kChunkRays];
  uint8_t shadow_flags_[kChunkRays];
  uint32_t batch_index_[kChunkRays];
  std::vector<uint8_t> stored_;  // sync reads
  store::AlignedBuffer scratch_;

  std::mutex inbox_mu_;
  std::condition_variable inbox_cv_;
  struct Delivery {
    uint32_t block;
    Status status;
  };
  std::vector<Delivery> inbox_, inbox_local_;
};

}  // namespace raystack::slave
