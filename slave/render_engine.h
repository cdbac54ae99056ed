#pragma once
// A slave's renderer: a block cache under a byte budget, a loader, and N ray threads, kept
// across frames so caches stay warm. RenderFrame traces one frame's tiles and hands finished
// samples to a sink.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "common/render/camera.h"
#include "common/render/frame_plan.h"
#include "common/render/material_table.h"
#include "common/render/sample_result.h"
#include "common/render/scene.h"
#include "common/store/store_reader.h"
#include "slave/block_cache.h"
#include "slave/block_loader.h"
#include "slave/block_source.h"
#include "common/store/store_bvh.h"
#include "slave/block_walk.h"
#include "slave/render_stats.h"
#include "slave/tile_source.h"

namespace raystack::slave {

enum class TraceMode { kStack, kSync, kIncore, kBvh };
const char* TraceModeName(TraceMode mode);
Expected<TraceMode> ParseTraceMode(const std::string& name);

struct EngineOptions {
  TraceMode mode = TraceMode::kStack;
  int threads = 2;
  double feed_fraction = 0.1;               // P_pr
  double tile_ahead = 0.0;                  // P_ra: ask for the next tile at this share done
  uint64_t cache_bytes = uint64_t{512} << 20;  // ignored in incore and bvh modes
  LoaderOptions loader;
  FaultOptions faults;
  size_t result_batch = 1024;               // samples per hand-over to the sink
  render::PixelOrder pixel_order = render::PixelOrder::kPriority;  // within a tile
};

class RayThread;

class RenderEngine {
 public:
  // `source`: where blocks come from instead of the store's own file (e.g. the peers, for
  // --blocks rem); it must outlive the engine.
  static Expected<std::unique_ptr<RenderEngine>> Create(const store::StoreReader& store,
                                                        EngineOptions options,
                                                        BlockSource* source = nullptr);
  ~RenderEngine();

  // Renders every tile `tiles` hands out, with `scene`'s lights, integrator and background,
  // through `camera`. Returns the first error (naming the block or file), after every thread
  // has stopped. After a failed frame the engine renders no more: the blocks its loader had
  // claimed and the pins its queues held are not unwound, so later frames return that error.
  Status RenderFrame(const render::Scene& scene, const render::MaterialTable& materials,
                     const render::Camera& camera, TileSource& tiles, render::SampleSink& sink,
                     RenderStats* stats);

  const BlockCache& cache() const { return *cache_; }
  const EngineOptions& options() const { return options_; }

 private:
  RenderEngine(const store::StoreReader& store, EngineOptions options);
  Status Preload(double* seconds);
  // bvh mode: the tree over every preloaded block's triangles.
  void BuildBvh(double* seconds);

  const store::StoreReader& store_;
  EngineOptions options_;
  std::unique_ptr<BlockCache> cache_;
  std::unique_ptr<DiskBlockSource> disk_;
  BlockSource* source_;  // disk_, or the one given to Create
  BlockWalk walk_;
  bool preloaded_ = false;
  Status failed_;  // the first failed frame's error
  std::unique_ptr<store::StoreBvh> bvh_;  // bvh mode: every triangle in one tree
  std::vector<std::unique_ptr<RayThread>> ray_threads_;  // made by the first frame
  BufferShelf read_buffers_;  // the loader's, from frame to frame
};

}  // namespace raystack::slave
