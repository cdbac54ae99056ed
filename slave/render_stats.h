#pragma once
// What one frame cost on one slave: the figures the thesis reports (TAB. VI.3-VI.4) and ours.

#include <array>
#include <cstdint>
#include <string>

#include "slave/ray_record.h"

namespace raystack::slave {

struct ThreadCounters {
  std::array<uint64_t, kRayTypeCount> rays{};  // rays created, by RayType
  uint64_t block_visits = 0;   // (ray, block) traversal steps
  uint64_t visits_waited = 0;  // steps whose block was not resident when the ray got there
  uint64_t samples = 0;        // samples finished
  uint64_t peak_stack_bytes = 0;
  uint64_t peak_stack_rays = 0;
  uint64_t peak_open_samples = 0;
  uint64_t peak_shadows_aside = 0;  // bvh mode: shadow rays put aside at once (RayThread::PutAside)
  // Stack mode: asleep with every ray waiting for the loader. Sync mode: reading a block, or
  // waiting for another thread's read of it (the time its I/O took from the thread).
  double idle_seconds = 0;
  double load_seconds = 0;  // sync mode: reading and decoding blocks (its T_io, summed)
  double tile_wait_seconds = 0;  // holding no rays, waiting for the tile source's next tile
  double run_seconds = 0;        // from the thread's start in the frame to its end
  double cpu_seconds = 0;        // CPU time the thread used in that span
};

struct RenderStats {
  std::string mode;
  int threads = 0;
  double seconds = 0;          // the frame, after any preloading
  double preload_seconds = 0;  // incore and bvh modes: loading every block first
  double bvh_build_seconds = 0;  // bvh mode: building the tree over every triangle
  std::array<uint64_t, kRayTypeCount> rays{};
  uint64_t rays_total = 0;
  double rays_per_second = 0;
  uint64_t samples = 0;
  uint64_t blocks_loaded = 0;    // #C, reloads included
  uint64_t blocks_distinct = 0;  // #U
  uint64_t block_count = 0;      // in the store
  uint64_t bytes_read = 0;       // stored bytes read from the block source
  uint64_t reads = 0;            // read requests (runs of neighbouring blocks)
  // The loader's I/O threads started (as reads piled up); with AIO, its decoding threads.
  uint64_t io_workers = 0;
  uint64_t loader_reads = 0;     // of `reads`, made by the loader thread itself (reads had not waited)
  bool direct_reads = false;     // blocks.bin read past the page cache (--direct-io)
  bool aio_reads = false;        // the loader kept those reads in flight with Linux AIO
  uint64_t aio_submits = 0;      // its io_submit calls: each one notification of the disk
  uint64_t block_visits = 0;
  double cache_hit_rate = 0;     // visits whose block was resident when the ray got there
  double loader_busy_seconds = 0;  // T_io: time with at least one read in flight
  double ray_idle_seconds = 0;     // summed over ray threads: asleep, every ray waiting for a block
  double ray_tile_wait_seconds = 0;  // summed over ray threads: no rays, waiting for a tile
  // Summed over ray threads: run time minus the two waits above, i.e. tracing and shading (in
  // sync mode a thread's own block reads count as busy). The master's utilisation.
  double ray_busy_seconds = 0;
  // CPU time, kernel included: summed over ray threads (in sync mode their own block reads
  // count here), and over the loader's threads (reading and decoding blocks; 0 in sync mode).
  // On a machine with fewer cores than threads, their sum over the cores bounds the frame.
  double ray_cpu_seconds = 0;
  double loader_cpu_seconds = 0;
  uint64_t cache_budget_bytes = 0;
  uint64_t cache_peak_bytes = 0;
  uint64_t evictions = 0;
  uint64_t peak_stack_bytes = 0;   // sum over threads of each one's peak queue memory
  uint64_t peak_stack_rays = 0;
  uint64_t peak_open_samples = 0;
  // bvh mode: the most shadow rays one thread put aside at once (RayThread::PutAside; not in
  // the JSON: a check of that bound, for the tests).
  uint64_t peak_shadows_aside = 0;
  uint64_t ray_record_bytes = sizeof(RayRecord);
  uint64_t peak_rss_bytes = 0;

  // One JSON object (stable keys, documented in the README).
  // `first`: fields put before the figures ("  \"key\": value,\n" lines: the frame's record).
  std::string ToJson(const std::string& first = "") const;
  // Human-readable lines for the end of a run.
  std::string ToText() const;
};

}  // namespace raystack::slave
