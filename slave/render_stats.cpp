#include "slave/render_stats.h"

#include <cstdio>
#include <limits>
#include <sstream>
#include <string>

#include "common/base/byte_sizes.h"
#include "common/base/log.h"

namespace raystack::slave {
namespace {
constexpr const char* kTypeNames[kRayTypeCount] = {"primary", "shadow", "specular", "diffuse"};
}

std::string RenderStats::ToJson(const std::string& first) const {
  std::ostringstream o;
  o.precision(12);  // (the stream's 6 digits gave "rays_per_second": 2.877e+06; a pipeline review)
  o << "{\n" << first << "  \"mode\": \"" << mode << "\",\n  \"threads\": " << threads
    << ",\n  \"seconds\": " << seconds << ",\n  \"preload_seconds\": " << preload_seconds
    << ",\n  \"bvh_build_seconds\": " << bvh_build_seconds << ",\n  \"rays\": {";
  for (int t = 0; t < kRayTypeCount; ++t)
    o << (t ? ", " : "") << "\"" << kTypeNames[t] << "\": " << rays[t];
  o << "},\n  \"rays_total\": " << rays_total << ",\n  \"rays_per_second\": " << rays_per_second
    << ",\n  \"samples\": " << samples << ",\n  \"blocks_loaded\": " << blocks_loaded
    << ",\n  \"blocks_distinct\": " << blocks_distinct << ",\n  \"block_count\": " << block_count
    << ",\n  \"loaded_per_useful\": "
    << (blocks_distinct ? static_cast<double>(blocks_loaded) / static_cast<double>(blocks_distinct) : 0.0)
    << ",\n  \"bytes_read\": " << bytes_read << ",\n  \"reads\": " << reads << ",\n  \"io_workers\": " << io_workers
    << ",\n  \"loader_reads\": " << loader_reads
    << ",\n  \"direct_reads\": " << (direct_reads ? "true" : "false")
    << ",\n  \"aio_reads\": " << (aio_reads ? "true" : "false")
    << ",\n  \"aio_submits\": " << aio_submits
    << ",\n  \"block_visits\": " << block_visits << ",\n  \"cache_hit_rate\": " << cache_hit_rate
    << ",\n  \"loader_busy_seconds\": " << loader_busy_seconds
    << ",\n  \"ray_idle_seconds\": " << ray_idle_seconds
    << ",\n  \"ray_tile_wait_seconds\": " << ray_tile_wait_seconds
    << ",\n  \"ray_busy_seconds\": " << ray_busy_seconds
    << ",\n  \"ray_cpu_seconds\": " << ray_cpu_seconds
    << ",\n  \"loader_cpu_seconds\": " << loader_cpu_seconds
    // No budget (in core): null, not 2^64 - 1, which a JSON reader in doubles misreads.
    << ",\n  \"cache_budget_bytes\": "
    << (cache_budget_bytes == std::numeric_limits<uint64_t>::max() ? std::string("null")
                                                                    : std::to_string(cache_budget_bytes))
    << ",\n  \"cache_peak_bytes\": " << cache_peak_bytes << ",\n  \"evictions\": " << evictions
    << ",\n  \"peak_stack_bytes\": " << peak_stack_bytes
    << ",\n  \"peak_stack_rays\": " << peak_stack_rays
    << ",\n  \"peak_open_samples\": " << peak_open_samples
    << ",\n  \"ray_record_bytes\": " << ray_record_bytes
    << ",\n  \"peak_rss_bytes\": " << peak_rss_bytes << "\n}\n";
  return o.str();
}

std::string RenderStats::ToText() const {
  std::string s = StrFormat("%s mode, %d thread%s: %.3f s", mode.c_str(), threads, threads == 1 ? "" : "s", seconds);
  if (preload_seconds > 0) s += StrFormat(" (+%.3f s preloading)", preload_seconds);
  if (bvh_build_seconds > 0) s += StrFormat(" (+%.3f s building the BVH)", bvh_build_seconds);
  s += StrFormat("\n  rays: %llu (%.2f M/s); primary %llu, shadow %llu, specular %llu, diffuse %llu",
                 static_cast<unsigned long long>(rays_total), rays_per_second * 1e-6,
                 static_cast<unsigned long long>(rays[0]), static_cast<unsigned long long>(rays[1]),
                 static_cast<unsigned long long>(rays[2]), static_cast<unsigned long long>(rays[3]));
  s += StrFormat("\n  blocks: %llu loaded (#C), %llu distinct used (#U) of %llu; %.1f MB read in %llu %s reads",
                 static_cast<unsigned long long>(blocks_loaded),
                 static_cast<unsigned long long>(blocks_distinct),
                 static_cast<unsigned long long>(block_count), static_cast<double>(bytes_read) / 1e6,
                 static_cast<unsigned long long>(reads),
                 aio_reads ? "direct (Linux AIO)" : direct_reads ? "direct" : "buffered");
  if (mode == "sync")  // no loader: each ray thread reads what it misses, and waits
    s += StrFormat(" (by the ray threads themselves, each waiting for its own); loading %.3f s, "
                   "ray threads waiting for reads %.3f s", loader_busy_seconds, ray_idle_seconds);
  else
    s += StrFormat(" (%llu by the loader itself, the rest by %llu I/O threads); loader busy %.3f s; "
                   "ray threads idle %.3f s", static_cast<unsigned long long>(loader_reads),
                   static_cast<unsigned long long>(io_workers), loader_busy_seconds, ray_idle_seconds);
  s += StrFormat("\n  ray threads: busy %.3f s, waiting for a tile %.3f s; CPU: ray threads %.3f s",
                 ray_busy_seconds, ray_tile_wait_seconds, ray_cpu_seconds);
  if (mode != "sync") s += StrFormat(", loader threads %.3f s", loader_cpu_seconds);
  // In core the cache has no budget (the largest byte count stands for none).
  const std::string budget =
      cache_budget_bytes == std::numeric_limits<uint64_t>::max()
          ? std::string("(no budget: in core)")
          : "of " + MiB(cache_budget_bytes);
  s += StrFormat("\n  cache: hit rate %.4f, peak %s %s, %llu evictions", cache_hit_rate,
                 MiB(cache_peak_bytes).c_str(), budget.c_str(),
                 static_cast<unsigned long long>(evictions));
  s += StrFormat("\n  ray stack: %llu-byte records, peak %.2f MB (%llu rays); peak RSS %.1f MB",
                 static_cast<unsigned long long>(ray_record_bytes),
                 static_cast<double>(peak_stack_bytes) / 1e6,
                 static_cast<unsigned long long>(peak_stack_rays),
                 static_cast<double>(peak_rss_bytes) / 1e6);
  return s;
}

}  // namespace raystack::slave
