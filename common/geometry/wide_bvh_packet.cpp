// WideBvh's packet walk: up to 8 coherent rays walk the tree as one, with bounds in place of
// a ray (see PacketRays), so a node is loaded and tested once for the packet. At a leaf each
// triangle's edge values are computed across the rays, 4 lanes at a time, and the rays inside
// take IntersectTriangle's last step (FinishTriangleHit) from them, with the triangle's plane
// computed once for all of them; a ray with a zero edge value takes IntersectTriangle itself.
//
// Results equal the single-ray walk's (wide_bvh.cpp) bit for bit: the bounds meet every box
// any of the rays meets there, the leaf tests are the single-ray ones lane by lane (the same
// float operations), and the closest-hit rule (CloserThan) does not depend on the order in
// which leaves are visited.

#include <algorithm>
#include <bit>
#include <cstring>
#include <limits>

#if defined(__SSE2__)  // every x86-64; elsewhere a packet's rays take the single-ray walk
#include <immintrin.h>
#endif

#include "common/base/check.h"
#include "common/geometry/next_float.h"
#include "common/geometry/wide_bvh.h"
#include "common/geometry/wide_bvh_internal.h"

namespace raystack {

using wide_bvh_internal::BoxRay;
using wide_bvh_internal::Corners;

constexpr int kLanes = WideBvh::kPacketSize;

#if defined(__SSE2__)
namespace {

// The leaves test the lanes in halves of 4, one SSE register each.
using VF = float __attribute__((vector_size(16)));
using VI = int32_t __attribute__((vector_size(16)));
constexpr int kHalves = kLanes / 4;

inline VF Splat(float x) { return VF{} + x; }

// Bit i set where lane i of a comparison result is true (all ones).
inline uint32_t Lanes(VI m) {
  __m128 bits;
  std::memcpy(&bits, &m, sizeof(bits));
  return static_cast<uint32_t>(_mm_movemask_ps(bits));
}

// What the rays of a packet must share: the shear axes (so a leaf's corners are read along the
// same axes in every lane) and the direction signs (so the same rows of a node's boxes are
// their near and far planes).
inline uint32_t PacketKey(const RayTriangleSetup& s, const BoxRay& b) {
  return static_cast<uint32_t>(s.kx | s.ky << 2 | s.kz << 4 | (b.near_row[0] != 0) << 6 |
                               (b.near_row[1] != 1) << 7 | (b.near_row[2] != 2) << 8);
}

inline bool HasParallelAxis(const BoxRay& b) {
  return std::isinf(b.inv_dir[0]) || std::isinf(b.inv_dir[1]) || std::isinf(b.inv_dir[2]);
}

// The packet's rays: for the nodes, the bounds of their box-test constants; for the leaves,
// their triangle-test constants lane by lane. Lanes outside the packet repeat its first ray
// and are never in a lane mask.
//
// The node test bounds, from the bounds of origin, 1/direction and pad, what every ray of
// the packet computes (NodeHits' float expressions): rounding is monotonic, so the same
// expressions on the right extremes give a lower bound of each ray's entry and an upper bound
// of its exit. A box any ray meets is met by the bounds. On a packet of rays from nearby
// pixels the bounds are tight, and one box test serves the whole packet.
struct PacketRays {
  // Per axis: the origin coordinate that gives the smallest (near plane) and the largest (far
  // plane) distance, the range of 1/direction (one sign: see PacketKey), the largest pad.
  float near_origin[3], far_origin[3], inv_lo[3], inv_hi[3], pad[3];
  int near_row[3], far_row[3];
  float tmin;  // the smallest ray.tmin
  // The triangle test, lane by lane: origin along kx, ky, kz; the shear.
  VF sheared_origin[3][kHalves], sx[kHalves], sy[kHalves];
  int kx, ky, kz;
  RayTriangleSetup setup[kLanes];
  float ray_tmin[kLanes];

  PacketRays(std::span<const Ray> rays, uint32_t lanes, const BoxRay* box,
             const RayTriangleSetup* tri)
      : box_(box) {
    const int first = std::countr_zero(lanes);
    kx = tri[first].kx;
    ky = tri[first].ky;
    kz = tri[first].kz;
    for (int i = 0; i < kLanes; ++i) {
      const int r = (lanes >> i & 1) ? i : first;
      sheared_origin[0][i / 4][i % 4] = tri[r].origin[kx];
      sheared_origin[1][i / 4][i % 4] = tri[r].origin[ky];
      sheared_origin[2][i / 4][i % 4] = tri[r].origin[kz];
      sx[i / 4][i % 4] = tri[r].sx;
      sy[i / 4][i % 4] = tri[r].sy;
      setup[i] = tri[r];
      ray_tmin[i] = rays[static_cast<size_t>(r)].tmin;
    }
    Bound(lanes);
  }

  // Sets the node test's bounds to those of the rays in `lanes` (not empty). Narrowed as rays
  // leave the search (any hit: once occluded), so the others' walk is not widened by them.
  void Bound(uint32_t lanes) {
    const int first = std::countr_zero(lanes);
    float o_lo[3], o_hi[3];
    for (int a = 0; a < 3; ++a) {
      near_row[a] = box_[first].near_row[a];
      far_row[a] = box_[first].far_row[a];
      o_lo[a] = o_hi[a] = box_[first].origin[a];
      inv_lo[a] = inv_hi[a] = box_[first].inv_dir[a];
      pad[a] = box_[first].pad[a];
    }
    tmin = ray_tmin[first];
    for (uint32_t b = lanes & (lanes - 1); b; b &= b - 1) {
      const int i = std::countr_zero(b);
      for (int a = 0; a < 3; ++a) {
        o_lo[a] = std::min(o_lo[a], box_[i].origin[a]);
        o_hi[a] = std::max(o_hi[a], box_[i].origin[a]);
        inv_lo[a] = std::min(inv_lo[a], box_[i].inv_dir[a]);
        inv_hi[a] = std::max(inv_hi[a], box_[i].inv_dir[a]);
        pad[a] = std::max(pad[a], box_[i].pad[a]);
      }
      tmin = std::min(tmin, ray_tmin[i]);
    }
    // (plane - origin) * inv: with inv > 0 it grows as the origin falls, so the near plane's
    // smallest value takes the largest origin and the far plane's largest the smallest; with
    // inv < 0 the other way round. Which of inv_lo and inv_hi gives the extreme depends on
    // the sign of (plane - origin), so PacketNodeHits takes the min (max) of both products.
    for (int a = 0; a < 3; ++a) {
      const bool positive = inv_lo[a] > 0;
      near_origin[a] = positive ? o_hi[a] : o_lo[a];
      far_origin[a] = positive ? o_lo[a] : o_hi[a];
    }
  }

 private:
  const BoxRay* box_;  // lane by lane
};

// Which of a node's boxes some ray of the packet may meet within [p.tmin, tmax] (tmax: the
// largest of the searching rays' bounds), and a lower bound of where each enters it.
template <typename NodeT>
inline uint32_t PacketNodeHits(const PacketRays& p, const NodeT& node, float tmax,
                               float t_enter[WideBvh::kWidth]) {
  constexpr float kFar = bvh_internal::kFarScale;
  uint32_t mask = 0;
  for (int half = 0; half < WideBvh::kWidth; half += 4) {
    __m128 t0 = _mm_set1_ps(p.tmin);
    __m128 t1 = _mm_set1_ps(tmax * kFar);
    for (int a = 0; a < 3; ++a) {
      const __m128 lo = _mm_set1_ps(p.inv_lo[a]), hi = _mm_set1_ps(p.inv_hi[a]);
      const __m128 pad = _mm_set1_ps(p.pad[a]);
      const __m128 dn = _mm_sub_ps(_mm_load_ps(node.box[p.near_row[a]] + half), _mm_set1_ps(p.near_origin[a]));
      const __m128 df = _mm_sub_ps(_mm_load_ps(node.box[p.far_row[a]] + half), _mm_set1_ps(p.far_origin[a]));
      const __m128 tn = _mm_sub_ps(_mm_min_ps(_mm_mul_ps(dn, lo), _mm_mul_ps(dn, hi)), pad);
      const __m128 tf = _mm_add_ps(
          _mm_mul_ps(_mm_max_ps(_mm_mul_ps(df, lo), _mm_mul_ps(df, hi)), _mm_set1_ps(kFar)), pad);
      t0 = _mm_max_ps(tn, t0);
      t1 = _mm_min_ps(tf, t1);
    }
    _mm_storeu_ps(t_enter + half, t0);
    mask |= static_cast<uint32_t>(_mm_movemask_ps(_mm_cmpngt_ps(t0, t1))) << half;
  }
  return mask;
}


}  // namespace

class WideBvhPacketWalk {
 public:
  using Node = WideBvh::Node;
  using Leaf = WideBvh::Leaf;

  // IntersectTriangle's edge values of every lane's ray on one triangle, computed across the
  // rays with its float operations: u, v, w are what it computes before its double fallback.
  struct Edges {
    alignas(16) float u[kLanes], v[kLanes], w[kLanes];
    uint32_t inside;  // the lanes whose u, v, w are all nonzero and of one sign
    uint32_t exact;   // the lanes with a zero among them, which IntersectTriangle decides in double
  };

  // The edge values of the rays in `lanes` on triangle k of `leaf` (other lanes: in neither
  // mask).
  static Edges EdgeValues(const PacketRays& p, const Leaf& leaf, uint32_t k, uint32_t lanes) {
    Edges e;
    uint32_t inside = 0, exact = 0;
    for (int h = 0; h < kHalves; ++h) {
      if ((lanes >> (4 * h) & 0xfu) == 0) continue;
      VF x[3], y[3];
      for (int c = 0; c < 3; ++c) {
        const VF dz = Splat(leaf.p[c][p.kz][k]) - p.sheared_origin[2][h];
        x[c] = (Splat(leaf.p[c][p.kx][k]) - p.sheared_origin[0][h]) - p.sx[h] * dz;
        y[c] = (Splat(leaf.p[c][p.ky][k]) - p.sheared_origin[1][h]) - p.sy[h] * dz;
      }
      const VF u = x[2] * y[1] - y[2] * x[1];
      const VF v = x[0] * y[2] - y[0] * x[2];
      const VF w = x[1] * y[0] - y[1] * x[0];
      std::memcpy(e.u + 4 * h, &u, sizeof(u));
      std::memcpy(e.v + 4 * h, &v, sizeof(v));
      std::memcpy(e.w + 4 * h, &w, sizeof(w));
      const VF zero{};
      const VI any_zero = (u == zero) | (v == zero) | (w == zero);
      const VI any_neg = (u < zero) | (v < zero) | (w < zero);
      const VI any_pos = (u > zero) | (v > zero) | (w > zero);
      inside |= Lanes(~any_zero & ~(any_neg & any_pos)) << (4 * h);
      exact |= Lanes(any_zero) << (4 * h);
    }
    e.inside = inside & lanes;
    e.exact = exact & lanes;
    return e;
  }

  // IntersectTriangle for lane i on triangle k, from its edge values: the exact lanes take
  // IntersectTriangle itself, the inside ones its last step with the triangle's plane.
  static bool LaneHit(const PacketRays& p, const Edges& e, int i, Vec3f p0, Vec3f p1, Vec3f p2,
                      const TrianglePlane& plane, float tmin, float tmax, float* t, float* u,
                      float* v) {
    if (e.exact >> i & 1) return IntersectTriangle(p.setup[i], p0, p1, p2, tmin, tmax, t, u, v);
    return FinishTriangleHit(p.setup[i], plane, e.u[i], e.v[i], e.w[i], tmin, tmax, t, u, v);
  }

  // WideBvh's walk with the packet's bounds in place of one ray; `*tmax` is the largest
  // bound among the lanes still searching.
  template <typename LeafFn>
  static void Traverse(const WideBvh& bvh, const PacketRays& p, const float* tmax, LeafFn&& leaf) {
    bvh.Traverse([&](const Node& node, float bound, float* t_enter) {
      return PacketNodeHits(p, node, bound, t_enter);
    }, tmax, leaf);
  }

  static uint32_t Intersect(const WideBvh& bvh, std::span<Hit> hits, uint32_t lanes,
                            const PacketRays& p) {
    // Per lane, as WideBvh::Intersect: hits equal to the best t are still tested.
    float tmax[kLanes];
    float largest = 0;
    for (uint32_t b = lanes; b; b &= b - 1) {
      const int i = std::countr_zero(b);
      tmax[i] = NextUp(hits[static_cast<size_t>(i)].t);
      largest = std::max(largest, tmax[i]);
    }
    uint32_t found = 0;
    Traverse(bvh, p, &largest, [&](uint32_t group, uint32_t n) {
      const Leaf& leaf = bvh.leaves_[group];
      bool closer = false;
      for (uint32_t k = 0; k < n; ++k) {
        const Edges e = EdgeValues(p, leaf, k, lanes);
        if ((e.inside | e.exact) == 0) continue;
        Vec3f p0, p1, p2;
        Corners(leaf.p, k, &p0, &p1, &p2);
        const TrianglePlane plane(p0, p1, p2);
        for (uint32_t c = e.inside | e.exact; c; c &= c - 1) {
          const int i = std::countr_zero(c);
          Hit& h = hits[static_cast<size_t>(i)];
          float t, u, v;
          if (LaneHit(p, e, i, p0, p1, p2, plane, p.ray_tmin[i], tmax[i], &t, &u, &v) &&
              CloserThan(t, leaf.id[k], h)) {
            h = {t, u, v, leaf.id[k], leaf.origin[k].block, leaf.origin[k].local};
            tmax[i] = NextUp(t);
            found |= 1u << i;
            closer = true;
          }
        }
      }
      if (closer) {
        largest = 0;
        for (uint32_t b = lanes; b; b &= b - 1) largest = std::max(largest, tmax[std::countr_zero(b)]);
      }
      return false;  // every leaf no lane's best hit has passed: a later one may be closer
    });
    return found;
  }

  static uint32_t Occluded(const WideBvh& bvh, std::span<const Ray> rays, uint32_t lanes,
                           PacketRays& p) {
    float largest = 0;
    for (uint32_t b = lanes; b; b &= b - 1) largest = std::max(largest, rays[static_cast<size_t>(std::countr_zero(b))].tmax);
    uint32_t searching = lanes;
    Traverse(bvh, p, &largest, [&](uint32_t group, uint32_t n) {
      const Leaf& leaf = bvh.leaves_[group];
      const uint32_t before = searching;
      for (uint32_t k = 0; k < n && searching != 0; ++k) {
        const Edges e = EdgeValues(p, leaf, k, searching);
        if ((e.inside | e.exact) == 0) continue;
        Vec3f p0, p1, p2;
        Corners(leaf.p, k, &p0, &p1, &p2);
        const TrianglePlane plane(p0, p1, p2);
        for (uint32_t c = e.inside | e.exact; c; c &= c - 1) {
          const int i = std::countr_zero(c);
          const Ray& r = rays[static_cast<size_t>(i)];
          float t, u, v;
          if (LaneHit(p, e, i, p0, p1, p2, plane, r.tmin, r.tmax, &t, &u, &v)) searching &= ~(1u << i);
        }
      }
      if (searching != before && searching != 0) {
        p.Bound(searching);
        largest = 0;
        for (uint32_t b = searching; b; b &= b - 1) largest = std::max(largest, rays[static_cast<size_t>(std::countr_zero(b))].tmax);
      }
      return searching == 0;
    });
    return lanes & ~searching;
  }
};

namespace {

// Splits rays[0 .. n) into packets and runs `walk(lanes, packet)` on each; a lone ray runs
// `single(i)`. A packet's rays share a PacketKey, point within kPacketCone of its first ray's
// direction and start within kPacketSpread of the model's size from its origin: the bounds of
// rays far apart would meet most of the tree (random rays in one packet: 10^5 nodes), so such
// rays are walked apart.
constexpr float kPacketCone = 0.995f;  // cosine: about 6 degrees
constexpr float kPacketSpread = 1.0f / 64;

template <typename Walk, typename Single>
uint32_t ForEachPacket(std::span<const Ray> rays, float magnitude, float extent, Walk&& walk,
                       Single&& single) {
  const float spread = extent * kPacketSpread;
  BoxRay box[kLanes];
  RayTriangleSetup tri[kLanes];
  uint32_t key[kLanes];
  bool parallel[kLanes];  // walked alone: the packet bounds need finite 1/direction
  Vec3f unit[kLanes];
  for (size_t i = 0; i < rays.size(); ++i) {
    unit[i] = Normalize(rays[i].direction);
    box[i] = BoxRay(rays[i], magnitude);
    tri[i] = RayTriangleSetup(rays[i]);
    key[i] = PacketKey(tri[i], box[i]);
    parallel[i] = HasParallelAxis(box[i]);
  }
  uint32_t result = 0;
  uint32_t left = rays.empty() ? 0 : (1u << rays.size()) - 1;
  while (left != 0) {
    const int first = std::countr_zero(left);
    uint32_t lanes = 1u << first;
    for (uint32_t b = parallel[first] ? 0 : left; b; b &= b - 1) {
      const int i = std::countr_zero(b);
      const Vec3f apart = rays[static_cast<size_t>(i)].origin - rays[static_cast<size_t>(first)].origin;
      if (key[i] == key[first] && !parallel[i] && Dot(unit[i], unit[first]) >= kPacketCone &&
          Dot(apart, apart) <= spread * spread)
        lanes |= 1u << i;
    }
    left &= ~lanes;
    if ((lanes & (lanes - 1)) == 0) {
      result |= single(first) ? lanes : 0;
    } else {
      result |= walk(lanes, PacketRays(rays, lanes, box, tri));
    }
  }
  return result;
}

}  // namespace

#endif  // __SSE2__

uint32_t WideBvh::IntersectPacket(std::span<const Ray> rays, std::span<Hit> hits) const {
  CHECK(hits.size() >= rays.size() && rays.size() <= static_cast<size_t>(kLanes));
#if defined(__SSE2__)
  return ForEachPacket(
      rays, magnitude_, extent_,
      [&](uint32_t lanes, const PacketRays& p) {
        return WideBvhPacketWalk::Intersect(*this, hits, lanes, p);
      },
      [&](int i) { return Intersect(rays[static_cast<size_t>(i)], &hits[static_cast<size_t>(i)]); });
#else
  uint32_t found = 0;
  for (size_t i = 0; i < rays.size(); ++i) found |= uint32_t{Intersect(rays[i], &hits[i])} << i;
  return found;
#endif
}

uint32_t WideBvh::OccludedPacket(std::span<const Ray> rays) const {
  CHECK(rays.size() <= static_cast<size_t>(kLanes));
#if defined(__SSE2__)
  return ForEachPacket(
      rays, magnitude_, extent_,
      [&](uint32_t lanes, PacketRays p) {
        return WideBvhPacketWalk::Occluded(*this, rays, lanes, p);
      },
      [&](int i) { return Occluded(rays[static_cast<size_t>(i)]); });
#else
  uint32_t occluded = 0;
  for (size_t i = 0; i < rays.size(); ++i) occluded |= uint32_t{Occluded(rays[i])} << i;
  return occluded;
#endif
}

}  // namespace raystack
