#include "slave/ray_thread.h"

#include <algorithm>
#include <chrono>
#include <memory>

#include "common/base/thread_cpu.h"
#include "common/render/pixel_priority.h"
#include "common/render/random.h"
#include "common/store/format.h"
#include "slave/block_walk.h"

namespace raystack::slave {

void FrameShared::Fail(const Status& status) {
  {
    std::lock_guard lock(error_mu);
    if (error.ok()) error = status;
  }
  abort.store(true);
  for (RayThread* t : threads) t->Wake();
  if (tiles) tiles->Abort();
}

RayThread::RayThread(uint32_t index, uint32_t block_count)
    : index_(index), queues_(block_count) {}

void RayThread::BeginFrame(FrameShared* shared) {
  shared_ = shared;
  queues_.Reset();
  slots_.Reset();
  counters_ = ThreadCounters{};
  tiles_.clear();
  newest_tile_ = 0;
  feed_next_ = feed_end_ = 0;
  feed_seq_ = 0;
  feed_total_ = feed_done_ = 0;
  free_chunks_.clear();
  open_tiles_ = 0;
  ahead_asked_ = false;
  tiles_exhausted_ = false;
  results_.clear();
  rays_reported_ = 0;
  pending_.clear();
  shadows_.clear();
  shadow_keys_.clear();
  taken_chunks_.clear();
  std::lock_guard lock(inbox_mu_);
  inbox_.clear();
  inbox_local_.clear();
}

void RayThread::Wake() {
  std::lock_guard lock(inbox_mu_);
  inbox_cv_.notify_all();
}

void RayThread::Deliver(uint32_t block, const Status& status) {
  {
    std::lock_guard lock(inbox_mu_);
    inbox_.push_back({block, status});
  }
  inbox_cv_.notify_all();
}

// ---------------------------------------------------------------------------------------------
// Feeding primary rays.

bool RayThread::NeedFeed() const {
  if (tiles_exhausted_) return false;
  if (tiles_.empty()) return true;
  const ActiveTile& t = tiles_[newest_tile_];
  // Thesis P_pr: the next tile's rays join once this fraction of the newest tile is done, so
  // the stack never runs dry at a tile's end yet stays small.
  return static_cast<double>(t.done) >= shared_->feed_fraction * static_cast<double>(t.total);
}

RayRecord RayThread::PrimaryRay(int x, int y, uint32_t sample, uint32_t slot,
                                uint16_t priority) const {
  // One sample per pixel goes through the pixel's centre (the camera's convention). With more,
  // every sample is jittered, the first too: a centred first sample weighed the centre's
  // colour 1/n too much, a bias at edges of order 1/n (an edge covering a quarter of a pixel
  // came out 0.125 at 2 samples, 0.20 at 4; found by a rendering researcher).
  float jx = 0.5f, jy = 0.5f;
  if (shared_->spp > 1) {
    const render::SampleRandom rng(shared_->seed, slots_.pixel(slot), sample);
    jx = rng.Uniform(0, render::RandomUse::kPixelJitterX);
    jy = rng.Uniform(0, render::RandomUse::kPixelJitterY);
  }
  Ray r = shared_->camera->Generate(static_cast<float>(x) + jx, static_cast<float>(y) + jy);
  shared_->approach.Approach(&r);
  RayRecord rec{};
  rec.origin = r.origin;
  rec.direction = r.direction;
  rec.tmax = r.tmax;
  rec.hit_id = kInvalidId;
  rec.slot = slot;
  rec.weight = {1, 1, 1};
  rec.material = store::kNoMaterial16;
  rec.type = static_cast<uint8_t>(RayType::kPrimary);
  rec.depth = 0;
  rec.priority = priority;
  return rec;
}

bool RayThread::FeedNextTile(bool may_wait) {
  if (feed_next_ < feed_end_) {  // the rest of the tile being fed comes first
    FeedChunk();
    return true;
  }
  if (may_wait) {
    FlushResults();
  } else if (!shared_->tiles->Ready(index_)) {
    shared_->tiles->Ahead(index_);  // asked now, taken once it has come
    return false;
  }
  Tile tile;
  const auto asked = std::chrono::steady_clock::now();
  const bool got = shared_->tiles->Next(index_, &tile);
  if (may_wait)  // (otherwise the tile was there: Next did not wait)
    counters_.tile_wait_seconds +=
        std::chrono::duration<double>(std::chrono::steady_clock::now() - asked).count();
  if (!got) {
    tiles_exhausted_ = true;
    return false;
  }
  const uint32_t sample_begin = tile.sample_begin;
  const uint32_t sample_end = tile.sample_end == 0 ? static_cast<uint32_t>(shared_->spp) : tile.sample_end;
  // The tile's pixels (those in its rank range) in the order they should finish: by priority,
  // or in scanline order, all of equal priority.
  const bool by_priority = shared_->pixel_order == render::PixelOrder::kPriority;
  feed_pixels_.clear();
  render::ForEachTilePixel(tile, by_priority, [&](int x, int y) {
    feed_pixels_.push_back({by_priority ? render::PixelPriority(x, y) : uint16_t{0}, x, y});
  });
  const uint32_t samples = sample_end > sample_begin ? sample_end - sample_begin : 0;
  feed_tile_ = tile;
  ++feed_seq_;
  feed_total_ = uint64_t{feed_pixels_.size()} * samples;
  feed_done_ = 0;
  if (feed_total_ == 0) {  // nothing in it (an empty rank range): an entry done at once
    newest_tile_ = NewChunk({tile, 0, 0, feed_seq_});
    free_chunks_.push_back(newest_tile_);
    feed_next_ = feed_end_ = 0;
    return true;
  }
  ahead_asked_ = false;
  feed_next_ = sample_begin;
  feed_end_ = sample_end;
  FeedChunk();
  return true;
}

uint32_t RayThread::NewChunk(const ActiveTile& chunk) {
  if (free_chunks_.empty()) {
    tiles_.push_back(chunk);
    return static_cast<uint32_t>(tiles_.size() - 1);
  }
  const uint32_t index = free_chunks_.back();
  free_chunks_.pop_back();
  tiles_[index] = chunk;
  return index;
}

void RayThread::FeedChunk() {
  const auto pixels = static_cast<uint32_t>(feed_pixels_.size());
  const uint32_t per_chunk = std::max(1u, shared_->max_feed_samples / pixels);
  const uint32_t sample_begin = feed_next_;
  const uint32_t sample_end = feed_end_ - sample_begin > per_chunk ? sample_begin + per_chunk
                                                                   : feed_end_;
  feed_next_ = sample_end;
  const uint32_t local = NewChunk({feed_tile_, pixels * (sample_end - sample_begin), 0, feed_seq_});
  newest_tile_ = local;
  ++open_tiles_;
  AskAhead();
  // Sample by sample, each over all the pixels; pending_ is a LIFO, so push in reverse.
  const int width = shared_->camera->width();
  const size_t first_fed = pending_.size();
  for (uint32_t s = sample_end; s-- > sample_begin;) {
    for (auto it = feed_pixels_.rbegin(); it != feed_pixels_.rend(); ++it) {
      const uint32_t pixel = static_cast<uint32_t>(it->y * width + it->x);
      const uint32_t slot = slots_.Open(pixel, s, local);
      pending_.push_back(PrimaryRay(it->x, it->y, s, slot, it->priority));
      ++counters_.rays[static_cast<int>(RayType::kPrimary)];
    }
  }
  if (shared_->bvh) PretraceBvh(first_fed, sample_begin, sample_end, feed_tile_);
  if (shared_->stack) {
    while (!pending_.empty()) {
      RayRecord r = pending_.back();
      pending_.pop_back();
      Route(r, kInvalidId);
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Per-ray steps shared by both drivers.

void RayThread::Finish(const RayRecord& ray) {
  const uint32_t slot = ray.slot;
  if (IsShadow(ray)) {  // reached the light
    slots_.AddRadiance(slot, ray.weight);
    RayDone(slot);
    return;
  }
  shared_->shader->Finish(ray, slots_.pixel(slot), slots_.sample(slot), &shade_);
  slots_.AddRadiance(slot, shade_.radiance);
  if (shade_.primary) {
    // A far camera's ray started nearer the model (primary_approach.h): depth from the camera.
    const double skipped = shade_.hit ? shared_->approach.Skipped(ray.origin) : 0;
    const float z = skipped > 0 ? static_cast<float>(double{shade_.z} + skipped) : shade_.z;
    slots_.SetPrimary(slot, shade_.hit, z, shade_.normal, shade_.albedo);
  }
  slots_.AddRays(slot, static_cast<uint32_t>(shade_.children.size()));
  for (const RayRecord& child : shade_.children) {
    ++counters_.rays[static_cast<int>(TypeOf(child))];
    pending_.push_back(child);
  }
  RayDone(slot);
}

void RayThread::RayDone(uint32_t slot) {
  const uint32_t tile = slots_.tile(slot);
  render::SampleResult result;
  if (!slots_.RayDone(slot, &result)) return;
  ++counters_.samples;
  const bool tile_done = ++tiles_[tile].done == tiles_[tile].total;
  if (tile_done) {
    --open_tiles_;
    free_chunks_.push_back(tile);  // (its entry stays readable until a new chunk takes it)
  }
  if (tiles_[tile].feed == feed_seq_) {  // a chunk of the tile being fed
    ++feed_done_;
    AskAhead();
  }
  results_.push_back(result);
  // A finished tile's samples go out at once rather than when a batch fills, so a progressive
  // frame's sparse first rounds reach the film (and the preview, and the log) as they are done.
  if (tile_done || results_.size() >= shared_->result_batch) FlushResults();
}

void RayThread::AskAhead() {
  if (ahead_asked_ || tiles_exhausted_) return;
  // Of the whole tile being fed (all its chunks, fed or not), as when a tile was fed at once.
  if (static_cast<double>(feed_done_) < shared_->tile_ahead * static_cast<double>(feed_total_))
    return;
  ahead_asked_ = true;
  shared_->tiles->Ahead(index_);
}

void RayThread::FlushResults() {
  if (results_.empty()) return;
  uint64_t rays = 0;
  for (uint64_t r : counters_.rays) rays += r;
  shared_->sink->Consume(results_, rays - rays_reported_);
  rays_reported_ = rays;
  results_.clear();
}

namespace {

// Records a closer hit found in `view`: distance, id, and what shading will need once the
// block may be gone (normal facing the ray's origin, side, material).
void RecordHit(const store::BlockView& view, const Hit& hit, RayRecord* ray) {
  Vec3f p0, p1, p2;
  view.TriangleVertices(hit.local_triangle, &p0, &p1, &p2);
  // Edges scaled first: the cross product of edges longer than ~1e19 or shorter than ~1e-19
  // would overflow or underflow float (and Normalize squares what it gets).
  const Vec3f ng = Cross(ScaledToUnitRange(p1 - p0), ScaledToUnitRange(p2 - p0));
  const bool back = Dot(ng, ray->direction) > 0;
  const Vec3f ng_facing = back ? -ng : ng;
  Vec3f ns = ng_facing;
  if (view.has_normals()) {
    const float w0 = 1.0f - hit.u - hit.v;
    const Vec3f n = view.Normal(view.VertexIndex(hit.local_triangle, 0)) * w0 +
                    view.Normal(view.VertexIndex(hit.local_triangle, 1)) * hit.u +
                    view.Normal(view.VertexIndex(hit.local_triangle, 2)) * hit.v;
    if (IsFinite(n) && Dot(n, n) > 0) ns = Dot(n, ng_facing) < 0 ? -n : n;
  }
  ray->tmax = hit.t;
  ray->hit_id = hit.triangle_id;
  ray->normal = EncodeNormal(Normalize(ScaledToUnitRange(ns)));
  ray->geometric_normal =
      view.has_normals() ? EncodeNormal(Normalize(ScaledToUnitRange(ng_facing))) : ray->normal;
  ray->flags = back ? kHitBackFace : 0;
  const uint32_t m = view.Material(hit.local_triangle);
  ray->material = m == store::kNoMaterial ? store::kNoMaterial16 : static_cast<uint16_t>(m);
}

// A waiting ray's geometry into *out, field by field: written in place, not built on the stack
// and copied (see TraceChunk).
void SetRay(const RayRecord& r, Ray* out) {
  out->origin = r.origin;
  out->direction = r.direction;
  out->tmin = 0;
  out->tmax = r.tmax;
}

Ray ToRay(const RayRecord& r) {
  Ray ray;
  SetRay(r, &ray);
  return ray;
}

Hit ToHit(const RayRecord& r) {
  Hit h;
  h.t = r.tmax;
  h.triangle_id = r.hit_id;
  return h;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Stack driver.

uint32_t RayThread::NextBlockOf(const RayRecord& ray, uint32_t from_block) const {
  const Ray r = ToRay(ray);
  if (from_block == kInvalidId) return shared_->walk->First(r);
  if (shared_->walk->DoneAfter(r, from_block)) return kInvalidId;
  return shared_->walk->Next(r, from_block);
}

void RayThread::Route(RayRecord& ray, uint32_t from_block) {
  const uint32_t block = NextBlockOf(ray, from_block);
  if (block == kInvalidId) {
    Finish(ray);
    return;
  }
  Enqueue(ray, block);
}

void RayThread::Enqueue(const RayRecord& ray, uint32_t block) {
  ++counters_.block_visits;
  uint32_t q = queues_.Find(block);
  if (q == RayQueues::kNone) {
    if (shared_->cache->TryAcquire(block)) {  // the ready queue holds this pin
      q = queues_.Create(block, RayQueues::State::kReady);
    } else {
      q = queues_.Create(block, RayQueues::State::kWaiting);
      shared_->loader->Request(block, index_);
    }
  }
  if (queues_.state(q) == RayQueues::State::kWaiting) ++counters_.visits_waited;
  queues_.Push(q, ray);
  counters_.peak_stack_bytes = std::max(counters_.peak_stack_bytes, queues_.peak_bytes());
  counters_.peak_stack_rays = std::max(counters_.peak_stack_rays, queues_.peak_rays());
}

void RayThread::TraceChunk(const store::BlockView& view, uint32_t block, RayRecord* rays,
                           uint32_t count) {
  DCHECK(count <= kChunkRays);
  // The batches are filled in place, field by field: a Ray or Hit built on the stack and then
  // copied in was read back through a failed store forward, every ray (two thirds of this
  // function's samples).
  uint32_t n = 0;
  for (uint32_t i = 0; i < count; ++i) {
    if (IsShadow(rays[i])) continue;
    SetRay(rays[i], &batch_rays_[n]);
    Hit& h = *std::construct_at(&batch_hits_[n]);
    h.t = rays[i].tmax;
    h.triangle_id = rays[i].hit_id;
    batch_index_[n++] = i;
  }
  view.IntersectBatch({batch_rays_, n}, {batch_hits_, n});
  for (uint32_t k = 0; k < n; ++k) {
    RayRecord& r = rays[batch_index_[k]];
    const Hit& h = batch_hits_[k];
    if (h.triangle_id != r.hit_id || h.t != r.tmax) RecordHit(view, h, &r);
  }
  n = 0;
  for (uint32_t i = 0; i < count; ++i) {
    if (!IsShadow(rays[i])) continue;
    SetRay(rays[i], &batch_rays_[n]);
    batch_index_[n++] = i;
  }
  view.OccludedBatch({batch_rays_, n}, {shadow_flags_, n});
  for (uint32_t k = 0; k < n; ++k)
    if (shadow_flags_[k]) rays[batch_index_[k]].flags |= kOccluded;
  // By reference, not copied: a copy's 16-byte stores cannot forward to NextBlockOf's 8-byte
  // load of direction.x and .y, which straddles two of them (a fifth of NextBlockOf's samples
  // waited there). The records do not move meanwhile: chunks are allocated one by one
  // (RayQueues keeps pointers to them), and the taken ones are ours until Recycle.
  for (uint32_t i = 0; i < count; ++i) {
    RayRecord& r = rays[i];
    if (r.flags & kOccluded) {
      RayDone(r.slot);  // blocked: the light contributes nothing
      continue;
    }
    Route(r, block);  // a finished ray's children land in pending_
  }
  while (!pending_.empty()) {
    RayRecord r = pending_.back();
    pending_.pop_back();
    Route(r, kInvalidId);
  }
}

void RayThread::TraceQueue(uint32_t q) {
  const uint32_t block = queues_.block(q);
  // The queue's pin keeps the block resident; this second pin only fetches the view.
  const store::BlockView* view = shared_->cache->TryAcquire(block);
  CHECK(view != nullptr);
  // A block the loader has just decoded is in the caches; one resident since an earlier tile
  // (a warm frame, a cache that holds the working set) mostly is not. Default scene, one
  // slave, every block resident: 654 -> 608 ns of ray-thread CPU per ray (5 interleaved runs);
  // with a cache that reloads, 567 -> 556 (tools/bench/RESULTS.md).
  view->Prefetch();
  while (queues_.size(q) > 0 && !shared_->abort.load(std::memory_order_relaxed)) {
    uint32_t last_count;
    queues_.TakeChunks(q, &taken_chunks_, &last_count);
    for (size_t c = 0; c < taken_chunks_.size(); ++c) {
      const uint32_t n = c + 1 == taken_chunks_.size() ? last_count : kChunkRays;
      TraceChunk(*view, block, queues_.chunk(taken_chunks_[c]).rays, n);
    }
    queues_.Recycle(taken_chunks_);
  }
  if (queues_.size(q) == 0) queues_.Close(q);
  shared_->cache->Release(block);
  shared_->cache->Release(block);
}

void RayThread::DrainInbox() {
  {
    std::lock_guard lock(inbox_mu_);
    inbox_local_.swap(inbox_);
    inbox_.clear();
  }
  for (const Delivery& d : inbox_local_) {
    if (!d.status.ok()) {
      shared_->Fail(d.status);
      continue;
    }
    const uint32_t q = queues_.Find(d.block);
    if (q == RayQueues::kNone || queues_.state(q) == RayQueues::State::kReady) {
      shared_->cache->Release(d.block);  // not needed (any more): give the pin back
      continue;
    }
    queues_.MarkReady(q);
  }
  inbox_local_.clear();
}

void RayThread::RunStack() {
  const auto began = std::chrono::steady_clock::now();
  const double cpu_began = ThreadCpuSeconds();
  while (!shared_->abort.load(std::memory_order_relaxed)) {
    DrainInbox();
    const uint32_t q = queues_.PopReady();
    if (q != RayQueues::kNone) {
      TraceQueue(q);
      continue;
    }
    if (NeedFeed() && FeedNextTile(/*may_wait=*/queues_.rays() == 0)) continue;
    // Every ray waits for the loader: rather than sleep, start another tile (a few at most,
    // which bounds the stack), so there is work to do while blocks are read, and more block
    // requests in flight to keep a slow disk or a network filesystem busy.
    if (queues_.rays() > 0 && !tiles_exhausted_ && open_tiles_ < kMaxOpenTiles &&
        queues_.rays() < kMostWaitingToOpenMore && FeedNextTile(/*may_wait=*/false))
      continue;
    if (queues_.rays() > 0) {  // everything waits for the loader
      FlushResults();
      const auto idle_start = std::chrono::steady_clock::now();
      {
        std::unique_lock lock(inbox_mu_);
        inbox_cv_.wait(lock, [&] { return !inbox_.empty() || shared_->abort.load(); });
      }
      counters_.idle_seconds +=
          std::chrono::duration<double>(std::chrono::steady_clock::now() - idle_start).count();
      continue;
    }
    if (tiles_exhausted_) break;
  }
  FlushResults();
  counters_.peak_open_samples = slots_.peak_open();
  counters_.run_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - began).count();
  counters_.cpu_seconds = ThreadCpuSeconds() - cpu_began;
}

// ---------------------------------------------------------------------------------------------
// Sync driver.

const store::BlockView* RayThread::AcquireSync(uint32_t block) {
  bool counted = false;
  while (!shared_->abort.load(std::memory_order_relaxed)) {
    if (const store::BlockView* view = shared_->cache->TryAcquire(block)) return view;
    if (!counted) {
      ++counters_.visits_waited;
      counted = true;
    }
    switch (shared_->cache->BeginLoad(block)) {
      case BlockCache::Claim::kLoad: {
        // The read is time waiting for I/O (idle; it was counted as busy, so sync showed no
        // wait at all with 1 ms per read); read and decode are this mode's T_io.
        const auto read_start = std::chrono::steady_clock::now();
        const uint32_t ids[1] = {block};
        Status s = shared_->source->ReadRun(ids, &stored_);
        const auto read_end = std::chrono::steady_clock::now();
        counters_.idle_seconds += std::chrono::duration<double>(read_end - read_start).count();
        if (!s.ok()) {
          shared_->cache->FailLoad(block, s);
          shared_->Fail(s);
          return nullptr;
        }
        s = shared_->cache->FinishLoad(block, stored_, 1, &scratch_);
        counters_.load_seconds +=
            std::chrono::duration<double>(std::chrono::steady_clock::now() - read_start).count();
        if (!s.ok()) {
          shared_->Fail(s);
          return nullptr;
        }
        const store::BlockView* view = shared_->cache->TryAcquire(block);
        shared_->cache->Release(block);  // keep exactly one pin
        return view;
      }
      case BlockCache::Claim::kLoading: {
        const auto wait_start = std::chrono::steady_clock::now();
        shared_->cache->WaitWhileLoading(block);
        counters_.idle_seconds +=
            std::chrono::duration<double>(std::chrono::steady_clock::now() - wait_start).count();
        break;
      }
      case BlockCache::Claim::kFailed:
        shared_->Fail(shared_->cache->FailureOf(block));
        return nullptr;
      case BlockCache::Claim::kResident:
      case BlockCache::Claim::kNoRoom:  // (only when asked not to wait)
        break;
    }
  }
  return nullptr;
}

void RayThread::TraceSync(RayRecord ray) {
  for (uint32_t from = kInvalidId;;) {
    const uint32_t block = NextBlockOf(ray, from);
    if (block == kInvalidId) {
      Finish(ray);
      return;
    }
    ++counters_.block_visits;
    const store::BlockView* view = AcquireSync(block);
    if (!view) return;  // the frame failed
    if (IsShadow(ray)) {
      const bool occluded = view->Occluded(ToRay(ray));
      shared_->cache->Release(block);
      if (occluded) {
        RayDone(ray.slot);
        return;
      }
    } else {
      Hit h = ToHit(ray);
      view->Intersect(ToRay(ray), &h);
      if (h.triangle_id != ray.hit_id || h.t != ray.tmax) RecordHit(*view, h, &ray);
      shared_->cache->Release(block);
    }
    from = block;
  }
}

void RayThread::PretraceBvh(size_t first, uint32_t sample_begin, uint32_t sample_end,
                            const Tile& tile) {
  // Sample s of the pixel at feed position p was pushed at (see FeedNextTile):
  const size_t pixels = feed_pixels_.size();
  auto pushed_at = [&](uint32_t s, size_t p) {
    return first + size_t{sample_end - 1 - s} * pixels + (pixels - 1 - p);
  };
  const int w = tile.x1 - tile.x0, h = tile.y1 - tile.y0;
  feed_grid_.assign(static_cast<size_t>(w) * static_cast<size_t>(h), -1);
  for (size_t p = 0; p < pixels; ++p) {
    const FeedPixel& f = feed_pixels_[p];
    feed_grid_[static_cast<size_t>((f.y - tile.y0) * w + (f.x - tile.x0))] = static_cast<int32_t>(p);
  }
  // Packets of 4 x 4 pixels (kPacketSize), row by row, so that each run of 8 is 4 x 2 where
  // the packet walk takes 8 rays at a time: primary rays through neighbouring pixels walk
  // nearly the same nodes (dragon: 8.3 nodes a packet of 8 against 6.6 a ray alone).
  static_assert(WideBvh::kPacketSize == 16);
  for (uint32_t s = sample_begin; s < sample_end; ++s) {
    for (int by = 0; by < h; by += 4) {
      for (int bx = 0; bx < w; bx += 4) {
        size_t index[WideBvh::kPacketSize];
        int n = 0;
        for (int y = by; y < std::min(by + 4, h); ++y)
          for (int x = bx; x < std::min(bx + 4, w); ++x)
            if (const int32_t p = feed_grid_[static_cast<size_t>(y * w + x)]; p >= 0)
              index[n++] = pushed_at(s, static_cast<size_t>(p));
        if (n != 0) TracePacket(index, n);
      }
    }
  }
}

void RayThread::TracePacket(const size_t* index, int n) {
  Ray rays[WideBvh::kPacketSize];
  Hit hits[WideBvh::kPacketSize];
  for (int j = 0; j < n; ++j) {
    rays[j] = ToRay(pending_[index[j]]);
    hits[j] = ToHit(pending_[index[j]]);
  }
  const auto count = static_cast<size_t>(n);
  const uint32_t found = shared_->bvh->IntersectPacket({rays, count}, {hits, count});
  for (int j = 0; j < n; ++j) {
    RayRecord& ray = pending_[index[j]];
    if (found >> j & 1) RecordBvhHit(hits[j], &ray);
    ray.flags |= kPretraced;
  }
}

void RayThread::TraceBvh(RayRecord ray) {
  if (ray.flags & kPretraced) {
    ray.flags &= static_cast<uint8_t>(~kPretraced);
    Finish(ray);
    return;
  }
  const store::StoreBvh& bvh = *shared_->bvh;
  if (IsShadow(ray)) {
    if (bvh.Occluded(ToRay(ray))) {
      RayDone(ray.slot);
      return;
    }
  } else {
    Hit h = ToHit(ray);
    if (bvh.Intersect(ToRay(ray), &h)) RecordBvhHit(h, &ray);
  }
  Finish(ray);
}

void RayThread::PutAside(const RayRecord& ray) {
  // A sample's shadow rays (one a light) are spawned together and popped in a row: the
  // ordinal counts them, so that the sort groups each light's rays of a pixel block (16 of one
  // pixel to 16 lights point every way: with 8 lights the frame was 8% slower, found by the
  // day's review).
  aside_ordinal_ = !shadows_.empty() && shadows_.back().slot == ray.slot ? aside_ordinal_ + 1 : 0;
  // Key: the pixel's 4 x 4 block (its row, then column), the ordinal, the pixel's place in the
  // block, the ray's index in shadows_.
  static_assert(render::kMaxImageSide / 4 <= (1 << 12) && kMaxShadowsAside <= (1u << 14));
  const auto width = static_cast<uint32_t>(shared_->camera->width());
  const uint32_t pixel = slots_.pixel(ray.slot);
  const uint64_t x = pixel % width, y = pixel / width;
  const uint64_t ordinal = std::min<uint64_t>(aside_ordinal_, (uint64_t{1} << 22) - 1);
  shadow_keys_.push_back((y / 4) << 52 | (x / 4) << 40 | ordinal << 18 | (y % 4) << 16 |
                         (x % 4) << 14 | shadows_.size());
  shadows_.push_back(ray);
  counters_.peak_shadows_aside = std::max<uint64_t>(counters_.peak_shadows_aside, shadows_.size());
}

void RayThread::TraceShadows() {
  // Popped one by one, the shadow rays of the primary hits of the samples fed together (a
  // tile's, at most FrameShared::kResidentFeedSamples at a time) come in the pixels' priority
  // order, spread over the tile; sorted by 4 x 4 pixel block and light (PutAside), 16 in a row
  // mostly leave neighbouring points for one point light, and walk the tree as one packet
  // (WideBvh::OccludedPacket). Only those are put aside (RunSync): shadow rays of later
  // bounces, or towards random points of emitters, point every way, and a tiny model's (the
  // Cornell box's) cost less alone than their packet's set-up (path tracing 8% slower when all
  // were). Results do not depend on the order in which rays finish (sample_slots.h sums
  // exactly), so the image is the same bit for bit; the samples of the rays put aside finish in
  // the sort's order rather than the pixels' priority order (within one feed: milliseconds).
  constexpr uint64_t kIndex = (uint64_t{1} << 14) - 1;
  std::sort(shadow_keys_.begin(), shadow_keys_.end());
  const store::StoreBvh& bvh = *shared_->bvh;
  constexpr size_t kPacket = WideBvh::kPacketSize;
  Ray rays[kPacket];
  for (size_t first = 0; first < shadow_keys_.size(); first += kPacket) {
    const size_t n = std::min(kPacket, shadow_keys_.size() - first);
    for (size_t j = 0; j < n; ++j) SetRay(shadows_[shadow_keys_[first + j] & kIndex], &rays[j]);
    const uint32_t occluded = bvh.OccludedPacket({rays, n});
    for (size_t j = 0; j < n; ++j) {
      const RayRecord& ray = shadows_[shadow_keys_[first + j] & kIndex];
      if (occluded >> j & 1)
        RayDone(ray.slot);
      else
        Finish(ray);  // reached the light
    }
  }
  shadows_.clear();
  shadow_keys_.clear();
}

void RayThread::RecordBvhHit(const Hit& hit, RayRecord* ray) {
  const store::BlockView* view = shared_->cache->ResidentView(hit.block_id);
  CHECK(view != nullptr);  // preloaded, and nothing is evicted without a budget
  RecordHit(*view, hit, ray);
}

void RayThread::RunSync() {
  const auto began = std::chrono::steady_clock::now();
  const double cpu_began = ThreadCpuSeconds();
  while (!shared_->abort.load(std::memory_order_relaxed)) {
    if (pending_.empty() && !FeedNextTile(/*may_wait=*/true)) break;
    while (!pending_.empty() && !shared_->abort.load(std::memory_order_relaxed)) {
      RayRecord r = pending_.back();  // depth first: children come back on top
      pending_.pop_back();
      if (!shared_->bvh) {
        TraceSync(r);
      } else if (IsShadow(r) && r.depth == 0 && shared_->shader->ShadowsEndAtPoints()) {
        PutAside(r);
        if (shadows_.size() >= kMaxShadowsAside) TraceShadows();
      } else {
        TraceBvh(r);
      }
    }
    if (!shadows_.empty() && !shared_->abort.load(std::memory_order_relaxed)) TraceShadows();
  }
  FlushResults();
  counters_.peak_open_samples = slots_.peak_open();
  counters_.run_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - began).count();
  counters_.cpu_seconds = ThreadCpuSeconds() - cpu_began;
}

}  // namespace raystack::slave
