#include "slave/render_engine.h"

#include <algorithm>
#include <chrono>
#include <new>
#include <system_error>
#include <thread>

#include "common/base/log.h"
#include "common/base/memory_available.h"
#include "common/base/thread_name.h"
#include "common/geometry/wide_bvh.h"
#include "slave/ray_thread.h"
#include "slave/shading.h"

namespace raystack::slave {

const char* TraceModeName(TraceMode mode) {
  switch (mode) {
    case TraceMode::kStack: return "stack";
    case TraceMode::kSync: return "sync";
    case TraceMode::kIncore: return "incore";
    case TraceMode::kBvh: return "bvh";
  }
  return "?";
}

Expected<TraceMode> ParseTraceMode(const std::string& name) {
  if (name == "stack") return TraceMode::kStack;
  if (name == "sync") return TraceMode::kSync;
  if (name == "incore") return TraceMode::kIncore;
  if (name == "bvh") return TraceMode::kBvh;
  return Status::Error("--mode must be stack, sync, incore or bvh, got '" + name + "'");
}

Expected<std::unique_ptr<RenderEngine>> RenderEngine::Create(const store::StoreReader& store,
                                                             EngineOptions options,
                                                             BlockSource* source) {
  if (options.threads < 1 || options.threads > BlockLoader::kMaxRayThreads)
    return Status::Error(StrFormat("--threads must be in [1, %d], got %d",
                                   BlockLoader::kMaxRayThreads, options.threads));
  if (!(options.feed_fraction >= 0 && options.feed_fraction <= 1))
    return Status::Error("--feed-fraction must be in [0, 1]");
  // Said before every block is read and the tree built, not by the build's internal check.
  if (options.mode == TraceMode::kBvh && store.summary().source_triangles > WideBvh::kMaxTriangles)
    return Status::Error(StrFormat(
        "%s: %llu triangles; --mode bvh builds one tree of at most %llu: --mode stack renders it",
        store.dir().c_str(), static_cast<unsigned long long>(store.summary().source_triangles),
        static_cast<unsigned long long>(WideBvh::kMaxTriangles)));
  std::unique_ptr<RenderEngine> engine(new RenderEngine(store, options));
  if (source) engine->source_ = source;
  const bool everything = options.mode == TraceMode::kIncore || options.mode == TraceMode::kBvh;
  const uint64_t budget = everything ? BlockCache::kUnlimited : options.cache_bytes;
  Expected<std::unique_ptr<BlockCache>> cache = BlockCache::Create(store, budget);
  if (!cache.ok()) return cache.status();
  engine->cache_ = std::move(*cache);
  return engine;
}

RenderEngine::RenderEngine(const store::StoreReader& store, EngineOptions options)
    : store_(store),
      options_(options),
      disk_(std::make_unique<DiskBlockSource>(store, options.faults)),
      source_(disk_.get()),
      walk_(store.octree(), store.blocks()) {}

RenderEngine::~RenderEngine() = default;

Status RenderEngine::Preload(double* seconds) {
  const auto start = std::chrono::steady_clock::now();
  // Every block, read in file order by all threads at once through the same path as a miss.
  std::atomic<uint32_t> next{0};
  std::mutex mu;
  Status error;
  auto work_on = [&] {
    std::vector<uint8_t> stored;
    store::AlignedBuffer scratch;
    for (;;) {
      const uint32_t id = next.fetch_add(1);
      if (id >= store_.blocks().size()) return;
      if (cache_->BeginLoad(id) != BlockCache::Claim::kLoad) continue;
      const uint32_t ids[1] = {id};
      Status s = source_->ReadRun(ids, &stored);
      if (s.ok()) {
        s = cache_->FinishLoad(id, stored, 0, &scratch);
      } else {
        cache_->FailLoad(id, s);
      }
      if (!s.ok()) {
        std::lock_guard lock(mu);
        if (error.ok()) error = s;
        next.store(static_cast<uint32_t>(store_.blocks().size()));
      }
    }
  };
  auto work = [&] {
    try {
      work_on();
    } catch (...) {  // out of memory (an address-space limit): out of a thread, std::terminate
      std::lock_guard lock(mu);
      if (error.ok()) error = Status::Error(kOutOfMemory);
      next.store(static_cast<uint32_t>(store_.blocks().size()));
    }
  };
  std::vector<std::thread> threads;
  for (int i = 0; i < options_.threads; ++i) {
    try {
      threads.emplace_back(work);
    } catch (...) {  // a limit on threads (ulimit -u, -v): fewer of them
      break;
    }
  }
  if (threads.empty()) work();
  for (std::thread& t : threads) t.join();
  *seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return ExplainShortFailure(error);
}

void RenderEngine::BuildBvh(double* seconds) {
  const auto start = std::chrono::steady_clock::now();
  // Every block is resident (the budget is unlimited): the views are pinned while the tree
  // copies their triangles, then given back.
  std::vector<store::BlockView> views(store_.blocks().size());
  for (uint32_t id = 0; id < views.size(); ++id) {
    const store::BlockView* v = cache_->TryAcquire(id);
    CHECK(v != nullptr);
    views[id] = *v;
  }
  bvh_ = std::make_unique<store::StoreBvh>(views, options_.threads);  // the ray threads' cores
  for (uint32_t id = 0; id < views.size(); ++id) cache_->Release(id);
  *seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  LOG_INFO("engine", "bvh mode: %zu triangles in one tree (%.1f MB), built in %.2f s",
           bvh_->triangle_count(), static_cast<double>(bvh_->bytes()) / 1e6, *seconds);
}

Status RenderEngine::RenderFrame(const render::Scene& scene,
                                 const render::MaterialTable& materials,
                                 const render::Camera& camera, TileSource& tiles,
                                 render::SampleSink& sink, RenderStats* stats) {
  if (!failed_.ok()) return failed_;
  RenderStats s;
  s.mode = TraceModeName(options_.mode);
  s.threads = options_.threads;
  // Counted from here: in incore mode the preloading is part of the frame's reads.
  cache_->StartFrame();
  const uint64_t loads_before = cache_->loads();
  const uint64_t distinct_before = cache_->distinct_loaded();
  const uint64_t bytes_before = source_->bytes_read();
  const uint64_t reads_before = source_->reads();
  const uint64_t evictions_before = cache_->evictions();
  if ((options_.mode == TraceMode::kIncore || options_.mode == TraceMode::kBvh) && !preloaded_) {
    // A failed preload fails the engine: a later frame would find blocks missing (and the bvh
    // mode's tree, built from every block, could not be).
    failed_ = Preload(&s.preload_seconds);
    if (!failed_.ok()) return failed_;
    preloaded_ = true;
  }
  if (options_.mode == TraceMode::kBvh && !bvh_) BuildBvh(&s.bvh_build_seconds);

  // The emitters path tracing aims at: the store's lights.bin with this scene's materials.
  const render::AreaLights area(store_.emitters(), materials);
  const Shader shader(scene, materials, &area);
  FrameShared shared;
  shared.store = &store_;
  shared.walk = &walk_;
  shared.cache = cache_.get();
  shared.source = source_;
  shared.shader = &shader;
  shared.camera = &camera;
  const store::StoreSummary& summary = store_.summary();
  shared.approach = PrimaryApproach(
      Bounds3f{{summary.model_lower[0], summary.model_lower[1], summary.model_lower[2]},
               {summary.model_upper[0], summary.model_upper[1], summary.model_upper[2]}},
      camera.position());
  shared.tiles = &tiles;
  shared.sink = &sink;
  shared.spp = scene.integrator.spp;
  shared.seed = scene.integrator.seed;
  shared.pixel_order = options_.pixel_order;
  shared.feed_fraction = options_.feed_fraction;
  shared.tile_ahead = options_.tile_ahead;
  shared.result_batch = options_.result_batch;
  if (cache_->budget() >= store_.summary().raw_bytes)  // every block stays resident
    shared.max_feed_samples = FrameShared::kResidentFeedSamples;
  // Whitted's hits each send a shadow ray to every point light at once: with many lights, a
  // chunk of several samples a pixel is cut to about kMostFedShadowRays (64 MB) of them, down
  // to one sample over the tile (the tiles a thread opens more are bounded by RayThread).
  if (scene.integrator.type == render::IntegratorType::kWhitted && !scene.lights.empty())
    shared.max_feed_samples = std::min<uint32_t>(
        shared.max_feed_samples,
        std::max<uint32_t>(1, static_cast<uint32_t>(FrameShared::kMostFedShadowRays / scene.lights.size())));
  shared.stack = options_.mode != TraceMode::kSync && options_.mode != TraceMode::kBvh;
  shared.bvh = bvh_.get();

  // The ray threads' memory is kept from frame to frame (see RayThread); the threads are not.
  std::vector<std::unique_ptr<RayThread>>& threads = ray_threads_;
  for (int i = static_cast<int>(threads.size()); i < options_.threads; ++i)
    threads.push_back(std::make_unique<RayThread>(static_cast<uint32_t>(i),
                                                  static_cast<uint32_t>(store_.blocks().size())));
  for (auto& t : threads) {
    t->BeginFrame(&shared);
    shared.threads.push_back(t.get());
  }

  std::unique_ptr<BlockLoader> loader;
  cache_->Reopen();  // the last frame's loader shut it
  const auto start = std::chrono::steady_clock::now();
  std::vector<std::thread> workers;
  try {
    workers.reserve(threads.size());
    if (shared.stack) {
      loader = std::make_unique<BlockLoader>(
          store_, cache_.get(), source_, options_.loader,
          [&threads](uint32_t thread, uint32_t block, const Status& status) {
            threads[thread]->Deliver(block, status);
          },
          &read_buffers_, [&shared](const Status& status) { shared.Fail(status); });
      shared.loader = loader.get();
    }
    for (auto& t : threads)
      workers.emplace_back([&shared, rt = t.get()] {
        SetThreadName("rs-ray");
        try {
          if (shared.stack)
            rt->RunStack();
          else
            rt->RunSync();
        } catch (...) {  // out of a thread: std::terminate; the frame fails (nothing allocated)
          shared.Fail(Status::Error(kOutOfMemory));
        }
      });
  } catch (...) {
    // A limit on threads or address space (ulimit -u, -v; std::thread's own state may not be
    // allocated either): the frame fails, and the threads started end first (a thread destroyed
    // while running is std::terminate). Nothing allocated here: said in full below.
    shared.Fail(Status::Error(kThreadRefused));
  }
  for (std::thread& w : workers) w.join();
  s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  s.direct_reads = store_.direct_reads();
  if (loader) {
    loader->Stop();
    s.loader_busy_seconds = loader->busy_seconds();
    s.loader_cpu_seconds = loader->cpu_seconds();
    s.io_workers = loader->workers();
    s.loader_reads = loader->inline_runs();
    s.aio_reads = loader->aio();
    s.aio_submits = loader->aio_submits();
  }

  uint64_t visits = 0, waited = 0;
  double sync_loads = 0;
  for (auto& t : threads) {
    const ThreadCounters& c = t->counters();
    for (int k = 0; k < kRayTypeCount; ++k) s.rays[k] += c.rays[k];
    s.samples += c.samples;
    visits += c.block_visits;
    waited += c.visits_waited;
    s.peak_stack_bytes += c.peak_stack_bytes;
    s.peak_stack_rays += c.peak_stack_rays;
    s.peak_open_samples += c.peak_open_samples;
    s.peak_shadows_aside = std::max(s.peak_shadows_aside, c.peak_shadows_aside);
    s.ray_idle_seconds += c.idle_seconds;
    s.ray_tile_wait_seconds += c.tile_wait_seconds;
    s.ray_busy_seconds += std::max(0.0, c.run_seconds - c.idle_seconds - c.tile_wait_seconds);
    s.ray_cpu_seconds += c.cpu_seconds;
    sync_loads += c.load_seconds;
  }
  if (!loader) s.loader_busy_seconds = sync_loads;  // sync: the ray threads' own loads
  for (uint64_t r : s.rays) s.rays_total += r;
  s.rays_per_second = s.seconds > 0 ? static_cast<double>(s.rays_total) / s.seconds : 0;
  s.block_visits = visits;
  s.cache_hit_rate = visits ? 1.0 - static_cast<double>(waited) / static_cast<double>(visits) : 1.0;
  s.blocks_loaded = cache_->loads() - loads_before;
  s.blocks_distinct = cache_->distinct_loaded() - distinct_before;
  s.block_count = store_.blocks().size();
  s.bytes_read = source_->bytes_read() - bytes_before;
  s.reads = source_->reads() - reads_before;
  s.evictions = cache_->evictions() - evictions_before;
  s.cache_budget_bytes = cache_->budget();
  s.cache_peak_bytes = cache_->peak_bytes();
  s.peak_rss_bytes = PeakRssBytes();
  if (stats) *stats = s;
  std::lock_guard lock(shared.error_mu);
  failed_ = ExplainShortFailure(shared.error);  // every thread has ended: memory is back
  return failed_;
}

}  // namespace raystack::slave
