// BlockView's batch queries: a block's queue of rays traced as packets of 4 rays that share
// a direction octant (see bvh_packet.h for why that keeps every result bit-identical to the
// single-ray forms).

#include <algorithm>
#include <cstdint>

#include "common/geometry/bvh_packet.h"
#include "common/store/block_view.h"

namespace raystack::store {
namespace {

// Rays are sorted by octant in chunks of this many, with the order kept on the stack.
constexpr int kChunk = 256;
static_assert(kChunk <= 65536, "ray order is kept in 16 bits");

// Calls packet(rays_of_packet, count) for every packet of up to 4 rays of one octant among
// rays [0, n) (n <= kChunk); `rays_of_packet` holds indices into the chunk.
template <typename PacketFn>
void ForEachPacket(std::span<const Ray> rays, PacketFn&& packet) {
  uint16_t octant[kChunk];
  int count[8] = {};
  const int n = static_cast<int>(rays.size());
  for (int i = 0; i < n; ++i) {
    octant[i] = static_cast<uint16_t>(DirectionOctant(rays[static_cast<size_t>(i)]));
    ++count[octant[i]];
  }
  int start[9] = {};
  for (int o = 0; o < 8; ++o) start[o + 1] = start[o] + count[o];
  uint16_t order[kChunk];
  int fill[8];
  std::copy(start, start + 8, fill);
  for (int i = 0; i < n; ++i) order[fill[octant[i]]++] = static_cast<uint16_t>(i);
  for (int o = 0; o < 8; ++o) {
    for (int i = start[o]; i < start[o + 1]; i += kPacketWidth) {
      packet(order + i, std::min(kPacketWidth, start[o + 1] - i));
    }
  }
}

}  // namespace

void BlockView::IntersectBatch(std::span<const Ray> rays, std::span<Hit> hits) const {
  DCHECK(rays.size() == hits.size());
  if (header_->node_count == 0) return;
  for (size_t base = 0; base < rays.size(); base += kChunk) {
    const size_t n = std::min<size_t>(kChunk, rays.size() - base);
    const std::span<const Ray> chunk = rays.subspan(base, n);
    Hit* const chunk_hits = hits.data() + base;
    ForEachPacket(chunk, [&](const uint16_t* index, int count) {
      const Ray* lane_ray[kPacketWidth];
      Hit* lane_hit[kPacketWidth];
      RayTriangleSetup setup[kPacketWidth];
      alignas(16) float tmax[kPacketWidth];
      for (int k = 0; k < kPacketWidth; ++k) {
        const int src = index[k < count ? k : 0];
        lane_ray[k] = &chunk[static_cast<size_t>(src)];
        lane_hit[k] = &chunk_hits[src];
        setup[k] = RayTriangleSetup(*lane_ray[k]);
        tmax[k] = NextUp(lane_hit[k]->t);
      }
      const RayPacket4 packet(lane_ray, count, magnitude_);
      TraverseBvhPacket4(nodes(), packet, (1 << count) - 1, tmax,
                         [&](int k, uint32_t first, uint32_t leaf_count) {
                           IntersectLeaf(setup[k], *lane_ray[k], first, leaf_count, &tmax[k],
                                         lane_hit[k]);
                           return false;
                         });
    });
  }
}

void BlockView::OccludedBatch(std::span<const Ray> rays, std::span<uint8_t> occluded) const {
  DCHECK(rays.size() == occluded.size());
  for (size_t base = 0; base < rays.size(); base += kChunk) {
    const size_t n = std::min<size_t>(kChunk, rays.size() - base);
    const std::span<const Ray> chunk = rays.subspan(base, n);
    uint8_t* const chunk_occluded = occluded.data() + base;
    for (size_t i = 0; i < n; ++i) chunk_occluded[i] = 0;
    if (header_->node_count == 0) continue;
    ForEachPacket(chunk, [&](const uint16_t* index, int count) {
      const Ray* lane_ray[kPacketWidth];
      RayTriangleSetup setup[kPacketWidth];
      alignas(16) float tmax[kPacketWidth];
      for (int k = 0; k < kPacketWidth; ++k) {
        lane_ray[k] = &chunk[index[k < count ? k : 0]];
        setup[k] = RayTriangleSetup(*lane_ray[k]);
        tmax[k] = lane_ray[k]->tmax;
      }
      const RayPacket4 packet(lane_ray, count, magnitude_);
      TraverseBvhPacket4(nodes(), packet, (1 << count) - 1, tmax,
                         [&](int k, uint32_t first, uint32_t leaf_count) {
                           if (!OccludedLeaf(setup[k], *lane_ray[k], first, leaf_count))
                             return false;
                           chunk_occluded[index[k]] = 1;
                           return true;
                         });
    });
  }
}

}  // namespace raystack::store
