// embree_bench: in-core rays/s of our store traversal against Embree 3 on the same mesh,
// rays and thread count. Ours: every block in memory, the octree walked front to back and
// each block's BVH traversed by BlockView, one ray at a time (StoreTracer) and batched per
// block as the renderer's ray stack does (BlockQueueTracer -> IntersectBatch). Embree: every
// ray API it offers; the best one is what we compare against. Also the one-BVH mode (StoreBvh),
// one ray at a time and in packets of 8 consecutive rays. A benchmark: it measures and
// checks agreement, it asserts nothing.
//   embree_bench STORE [--width W] [--height H] [--random N] [--threads 1,2] [--repeats R]
//                      [--pairs P] [--chunk RAYS] [--cpu-time 0|1] [--ours-only 0|1]
//                      [--embree-robust 0|1] [--walks baseline|avx2|avx512]
// The table's ratios divide figures measured one after the other; on a VM whose speed drifts
// by 10-20% within a minute they move with the drift. So each row is followed by paired
// ratios: ours (one BVH, and packets) and the best Embree API timed alternately P times, the
// ratio taken within each pair, their median and range printed.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "common/store/block_codec.h"
#include "common/store/store_reader.h"
#include "common/store/store_bvh.h"
#include "common/store/store_tracer.h"
#include "tools/bench/bench_rays.h"
#include "tools/bench/block_queue_tracer.h"
#include "tools/bench/embree_tracer.h"

using namespace raystack;
using namespace raystack::bench;

namespace {

struct Options {
  std::string store;
  int width = 1024, height = 1024, random = 1000000, repeats = 3;
  int pairs = 7;  // ours and the best Embree API alternated, for the paired ratios
  size_t chunk = 65536;  // rays per BlockQueueTracer call (one wave of the ray stack)
  std::vector<int> threads{1, 2};
  bool cpu_time = false;  // CPU seconds instead of wall seconds
  bool ours_only = false;
  // Embree's robust mode: watertight triangle tests, as ours always are. Off by default: the
  // fastest Embree is the figure the targets are read against; on, the like-for-like one.
  bool embree_robust = false;
  // The widest copy of our one-BVH walks to use (WideBvh::LimitWalks): the widest the CPU has.
  WideBvh::WalkIsa walks = WideBvh::WalkIsa::kAvx512;
};

[[noreturn]] void Usage() {
  std::fprintf(stderr,
               "usage: embree_bench STORE [--width W] [--height H] [--random N] "
               "[--threads 1,2] [--repeats R] [--pairs P] [--chunk RAYS] [--cpu-time 0|1] "
               "[--ours-only 0|1] [--embree-robust 0|1] [--walks baseline|avx2|avx512]\n");
  std::exit(2);
}

Options Parse(int argc, char** argv) {
  Options o;
  if (argc < 2 || argv[1][0] == '-') Usage();  // --help, or an option where STORE belongs
  o.store = argv[1];
  for (int i = 2; i < argc; i += 2) {
    if (i + 1 >= argc) Usage();
    const char* v = argv[i + 1];
    if (!std::strcmp(argv[i], "--width")) o.width = std::atoi(v);
    else if (!std::strcmp(argv[i], "--height")) o.height = std::atoi(v);
    else if (!std::strcmp(argv[i], "--random")) o.random = std::atoi(v);
    else if (!std::strcmp(argv[i], "--repeats")) o.repeats = std::max(1, std::atoi(v));
    else if (!std::strcmp(argv[i], "--pairs")) o.pairs = std::max(0, std::atoi(v));
    else if (!std::strcmp(argv[i], "--cpu-time")) o.cpu_time = std::atoi(v) != 0;
    else if (!std::strcmp(argv[i], "--ours-only")) o.ours_only = std::atoi(v) != 0;
    else if (!std::strcmp(argv[i], "--embree-robust")) o.embree_robust = std::atoi(v) != 0;
    else if (!std::strcmp(argv[i], "--walks")) {
      using Isa = WideBvh::WalkIsa;
      if (!std::strcmp(v, "baseline")) o.walks = Isa::kBaseline;
      else if (!std::strcmp(v, "avx2")) o.walks = Isa::kAvx2;
      else if (!std::strcmp(v, "avx512")) o.walks = Isa::kAvx512;
      else Usage();
    } else if (!std::strcmp(argv[i], "--chunk")) o.chunk = static_cast<size_t>(std::atol(v));
    else if (!std::strcmp(argv[i], "--threads")) {
      o.threads.clear();
      for (const char* p = v; *p;) {
        o.threads.push_back(std::max(1, std::atoi(p)));
        p = std::strchr(p, ',');
        if (!p) break;
        ++p;
      }
    } else {
      Usage();
    }
  }
  if (o.width % 4 || o.height % 4) Usage();
  return o;
}

// Every block parsed in memory, for the batched path.
struct InCore {
  std::vector<store::AlignedBuffer> raw;
  std::vector<store::BlockView> views;
};

InCore LoadBlocks(const store::StoreReader& s) {
  InCore c;
  c.raw.resize(s.blocks().size());
  std::vector<uint8_t> stored;
  store::AlignedBuffer scratch;
  for (uint32_t id = 0; id < s.blocks().size(); ++id) {
    Expected<store::BlockView> v = s.Load(id, &stored, &scratch, &c.raw[id]);
    if (!v.ok()) {
      std::fprintf(stderr, "embree_bench: %s\n", v.status().message().c_str());
      std::exit(1);
    }
    c.views.push_back(*v);
  }
  return c;
}

// The source triangles, each once (a triangle crossing cells is stored in several blocks).
std::vector<Vec3f> SourceTriangles(std::span<const store::BlockView> views) {
  std::vector<uint8_t> seen;
  std::vector<Vec3f> vertices;
  for (const store::BlockView& v : views) {
    for (uint32_t t = 0; t < v.triangle_count(); ++t) {
      const uint32_t id = v.TriangleId(t);
      if (id >= seen.size()) seen.resize(id + 1, 0);
      if (seen[id]) continue;
      seen[id] = 1;
      Vec3f p[3];
      v.TriangleVertices(t, &p[0], &p[1], &p[2]);
      vertices.insert(vertices.end(), p, p + 3);
    }
  }
  return vertices;
}

bool SameHit(const Hit& a, const Hit& b) {
  return std::memcmp(&a.t, &b.t, sizeof(float)) == 0 && a.u == b.u && a.v == b.v &&
         a.triangle_id == b.triangle_id && a.block_id == b.block_id &&
         a.local_triangle == b.local_triangle;
}

bool SameSurfaceHit(const Hit& a, const Hit& b) {
  return std::memcmp(&a.t, &b.t, sizeof(float)) == 0 && a.u == b.u && a.v == b.v &&
         a.triangle_id == b.triangle_id;
}

bool CloseT(float ours, float theirs) {
  if (std::isinf(ours) || std::isinf(theirs)) return std::isinf(ours) && std::isinf(theirs);
  return std::fabs(ours - theirs) <= 1e-4f * std::fabs(ours);
}

struct Kind {
  const char* name;
  std::vector<Ray> rays;
  bool closest;   // closest hit, else any hit
  bool coherent;  // Embree's context flag
};

}  // namespace

int main(int argc, char** argv) {
  const Options o = Parse(argc, argv);
  Expected<std::unique_ptr<store::StoreReader>> opened = store::StoreReader::Open(o.store);
  if (!opened.ok()) {
    std::fprintf(stderr, "embree_bench: %s\n", opened.status().message().c_str());
    return 1;
  }
  const store::StoreReader& s = **opened;
  store::StoreTracer tracer(s);
  if (Status st = tracer.LoadAll(); !st.ok()) {
    std::fprintf(stderr, "embree_bench: %s\n", st.message().c_str());
    return 1;
  }
  const InCore in_core = LoadBlocks(s);
  const auto build_began = std::chrono::steady_clock::now();
  const store::StoreBvh flat(in_core.views);
  const double build_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - build_began).count();
  const std::vector<Vec3f> vertices = SourceTriangles(in_core.views);
  const int max_threads = *std::max_element(o.threads.begin(), o.threads.end());
  const EmbreeTracer embree(vertices, max_threads, o.embree_robust);
  std::printf("store %s: %zu blocks, %zu source triangles; Embree %s, robust mode %s\n",
              o.store.c_str(), s.blocks().size(), vertices.size() / 3, embree.Version().c_str(),
              o.embree_robust ? "on" : "off");
  std::printf("our one-BVH walks: %s\n", WideBvh::WalkIsaName(WideBvh::LimitWalks(o.walks)));
  std::printf("one BVH (StoreBvh): built in %.2f s, %.1f MB\n", build_seconds,
              static_cast<double>(flat.bytes()) / 1e6);

  const Bounds3f model = s.model_bounds();
  const Camera camera = FrameModel(model);
  std::vector<Kind> kinds;
  kinds.push_back({"primary", PrimaryRays(camera, o.width, o.height), true, true});
  {
    std::vector<Hit> hits(kinds[0].rays.size());
    BlockQueueTracer q(s.octree(), in_core.views);
    q.Intersect(kinds[0].rays, hits);
    kinds.push_back({"shadow", ShadowRays(kinds[0].rays, hits, LightFor(model, camera)), false,
                     true});
  }
  kinds.push_back({"random", RandomRays(model, o.random, 1), true, false});

  const EmbreeApi apis[] = {EmbreeApi::kSingle, EmbreeApi::kPacket4, EmbreeApi::kPacket8,
                            EmbreeApi::kPacket16, EmbreeApi::kStream};
  std::printf("\n| rays | n | threads | ours single | ours batched | mean batch | ours one BVH | ours one BVH, packets of %d |", WideBvh::kPacketSize);
  for (EmbreeApi api : apis) std::printf(" %s |", EmbreeApiName(api));
  std::printf(" best Embree | single/Embree | batched/Embree | one BVH/Embree | packets/Embree |\n|---|---:|---:|---:|---:|---:|---:|---:|");
  for (size_t i = 0; i < std::size(apis); ++i) std::printf("---:|");
  std::printf("---|---:|---:|---:|---:|\n");

  std::string paired_rows;  // printed after the table
  for (const Kind& kind : kinds) {
    const size_t n = kind.rays.size();
    const std::span<const Ray> rays = kind.rays;
    std::vector<Hit> single_hits(n), batch_hits(n), flat_hits(n), packet_hits(n);
    std::vector<uint8_t> single_occ(n), batch_occ(n), flat_occ(n), packet_occ(n), embree_occ(n);
    std::vector<Hit> embree_hits(n);
    for (int threads : o.threads) {
      const double single = MedianSeconds(o.repeats, [&] {
        ParallelChunks(threads, n, 4096, [&](size_t b, size_t e, int) {
          for (size_t i = b; i < e; ++i) {
            if (kind.closest) {
              single_hits[i] = tracer.Intersect(rays[i]).value();
            } else {
              single_occ[i] = tracer.Occluded(rays[i]).value() ? 1 : 0;
            }
          }
        });
      }, o.cpu_time);
      std::vector<BlockQueueTracer> queues(static_cast<size_t>(threads),
                                           BlockQueueTracer(s.octree(), in_core.views));
      const double batched = MedianSeconds(o.repeats, [&] {
        ParallelChunks(threads, n, o.chunk, [&](size_t b, size_t e, int t) {
          BlockQueueTracer& q = queues[static_cast<size_t>(t)];
          if (kind.closest) {
            q.Intersect(rays.subspan(b, e - b), std::span<Hit>(batch_hits).subspan(b, e - b));
          } else {
            q.Occluded(rays.subspan(b, e - b), std::span<uint8_t>(batch_occ).subspan(b, e - b));
          }
        });
      }, o.cpu_time);
      auto run_one_bvh = [&] {
        ParallelChunks(threads, n, 4096, [&](size_t b, size_t e, int) {
          for (size_t i = b; i < e; ++i) {
            if (kind.closest) {
              flat_hits[i] = flat.Intersect(rays[i]);
            } else {
              flat_occ[i] = flat.Occluded(rays[i]) ? 1 : 0;
            }
          }
        });
      };
      const double one_bvh = MedianSeconds(o.repeats, run_one_bvh, o.cpu_time);
      // Consecutive rays as packets: PrimaryRays lists 4 x 4 pixel blocks, ShadowRays keeps
      // their order (the packet walk splits off rays too far apart; random rays all are).
      auto run_packets = [&] {
        ParallelChunks(threads, n, 4096, [&](size_t b, size_t e, int) {
          for (size_t i = b; i < e; i += WideBvh::kPacketSize) {
            const size_t m = std::min<size_t>(WideBvh::kPacketSize, e - i);
            if (kind.closest) {
              for (size_t j = i; j < i + m; ++j) packet_hits[j] = Hit{rays[j].tmax};
              flat.IntersectPacket(rays.subspan(i, m), std::span<Hit>(packet_hits).subspan(i, m));
              for (size_t j = i; j < i + m; ++j)
                if (!packet_hits[j].Valid()) packet_hits[j].t = std::numeric_limits<float>::infinity();
            } else {
              const uint32_t occluded = flat.OccludedPacket(rays.subspan(i, m));
              for (size_t j = 0; j < m; ++j) packet_occ[i + j] = (occluded >> j) & 1;
            }
          }
        });
      };
      const double packets = MedianSeconds(o.repeats, run_packets, o.cpu_time);
      uint64_t visits = 0, batches = 0;
      for (const BlockQueueTracer& q : queues) {
        visits += q.ray_block_visits();
        batches += q.batches();
      }
      // Batched must equal single bit for bit; Embree must agree within 1e-4 (relative t).
      // One BVH keeps a triangle once, so its hit may name another block's copy: compare
      // everything else.
      size_t batch_mismatch = 0, flat_mismatch = 0, packet_mismatch = 0;
      for (size_t i = 0; i < n; ++i) {
        packet_mismatch += kind.closest ? !SameSurfaceHit(single_hits[i], packet_hits[i])
                                        : single_occ[i] != packet_occ[i];
        batch_mismatch += kind.closest ? !SameHit(single_hits[i], batch_hits[i])
                                       : single_occ[i] != batch_occ[i];
        flat_mismatch += kind.closest ? !SameSurfaceHit(single_hits[i], flat_hits[i])
                                      : single_occ[i] != flat_occ[i];
      }
      std::printf("| %s | %zu | %d | %.2f | %.2f | %.0f | %.2f | %.2f |", kind.name, n, threads,
                  static_cast<double>(n) / single / 1e6, static_cast<double>(n) / batched / 1e6,
                  static_cast<double>(visits) / static_cast<double>(std::max<uint64_t>(1, batches)),
                  static_cast<double>(n) / one_bvh / 1e6, static_cast<double>(n) / packets / 1e6);
      auto run_embree = [&](EmbreeApi api) {
        ParallelChunks(threads, n, 4096, [&](size_t b, size_t e, int) {
          if (kind.closest) {
            embree.Intersect(api, kind.coherent, rays.subspan(b, e - b),
                             std::span<Hit>(embree_hits).subspan(b, e - b));
          } else {
            embree.Occluded(api, kind.coherent, rays.subspan(b, e - b),
                            std::span<uint8_t>(embree_occ).subspan(b, e - b));
          }
        });
      };
      double best = 0;
      const char* best_name = "";
      EmbreeApi best_api = EmbreeApi::kSingle;
      std::string agreement;
      for (EmbreeApi api : apis) {
        if (o.ours_only || !embree.Supports(api)) {
          std::printf(" n/a |");
          continue;
        }
        const double sec = MedianSeconds(o.repeats, [&] { run_embree(api); }, o.cpu_time);
        size_t agree = 0;
        for (size_t i = 0; i < n; ++i) {
          agree += kind.closest ? CloseT(single_hits[i].t, embree_hits[i].t)
                                : single_occ[i] == embree_occ[i];
        }
        char buffer[96];
        std::snprintf(buffer, sizeof(buffer), " %s %.3f%%;", EmbreeApiName(api),
                      100.0 * static_cast<double>(agree) / static_cast<double>(n));
        agreement += buffer;
        const double rate = static_cast<double>(n) / sec / 1e6;
        std::printf(" %.2f |", rate);
        if (rate > best) {
          best = rate;
          best_name = EmbreeApiName(api);
          best_api = api;
        }
      }
      std::printf(" %.2f (%s) | %.2f | %.2f | %.2f | %.2f |\n", best, best_name,
                  static_cast<double>(n) / single / 1e6 / best,
                  static_cast<double>(n) / batched / 1e6 / best,
                  static_cast<double>(n) / one_bvh / 1e6 / best,
                  static_cast<double>(n) / packets / 1e6 / best);
      std::fprintf(stderr,
                   "  %s x%d: batched != single on %zu rays, one BVH != single on %zu, packets "
                   "!= single on %zu; Embree agrees:%s\n",
                   kind.name, threads, batch_mismatch, flat_mismatch, packet_mismatch,
                   agreement.c_str());
      if (best > 0 && o.pairs > 0) {
        // Paired: the best Embree API timed between our two walks, so a drift of the machine's
        // speed moves both sides of each ratio alike.
        std::vector<double> one_bvh_ratio, packets_ratio;
        for (int p = 0; p < o.pairs; ++p) {
          const double ours_one = MedianSeconds(1, run_one_bvh, o.cpu_time);
          const double theirs = MedianSeconds(1, [&] { run_embree(best_api); }, o.cpu_time);
          const double ours_packets = MedianSeconds(1, run_packets, o.cpu_time);
          one_bvh_ratio.push_back(theirs / ours_one);
          packets_ratio.push_back(theirs / ours_packets);
        }
        auto summary = [](std::vector<double> r) {
          std::sort(r.begin(), r.end());
          char text[64];
          std::snprintf(text, sizeof(text), "%.2f (%.2f-%.2f)", r[r.size() / 2], r.front(),
                        r.back());
          return std::string(text);
        };
        char row[256];
        std::snprintf(row, sizeof(row), "| %s | %d | %s | %s | %s |\n", kind.name, threads,
                      best_name, summary(one_bvh_ratio).c_str(), summary(packets_ratio).c_str());
        paired_rows += row;
      }
    }
  }
  if (!paired_rows.empty()) {
    std::printf("\nPaired ratios: ours and the best Embree API above timed alternately, %d pairs, "
                "the ratio taken within each pair: median (range)\n\n"
                "| rays | threads | Embree API | one BVH / Embree | packets / Embree |\n"
                "|---|---:|---|---:|---:|\n%s",
                o.pairs, paired_rows.c_str());
  }
  return 0;
}
