#include "common/geometry/wide_bvh.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "common/geometry/next_float.h"
#include "common/geometry/triangle.h"
#include "tests/geometry/test_meshes.h"

namespace raystack {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

struct Mesh {
  std::vector<Vec3f> vertices;  // 3 per triangle
  std::vector<uint32_t> ids;
  std::vector<TriangleOrigin> origins;  // (7 i + 1, i) for triangle i
  void Add(Vec3f a, Vec3f b, Vec3f c, uint32_t id) {
    vertices.insert(vertices.end(), {a, b, c});
    origins.push_back({7 * static_cast<uint32_t>(ids.size()) + 1, static_cast<uint32_t>(ids.size())});
    ids.push_back(id);
  }
};

// Every triangle tested, the closest kept by CloserThan: the answer any traversal must give.
Hit BruteIntersect(const Mesh& m, const Ray& ray, Hit hit) {
  const RayTriangleSetup s(ray);
  for (uint32_t i = 0; i < m.ids.size(); ++i) {
    float t, u, v;
    if (IntersectTriangle(s, m.vertices[3 * i], m.vertices[3 * i + 1], m.vertices[3 * i + 2],
                          ray.tmin, NextUp(hit.t), &t, &u, &v) &&
        CloserThan(t, m.ids[i], hit)) {
      hit.t = t;
      hit.u = u;
      hit.v = v;
      hit.triangle_id = m.ids[i];
      hit.block_id = m.origins[i].block;
      hit.local_triangle = m.origins[i].local;
    }
  }
  return hit;
}

bool BruteOccluded(const Mesh& m, const Ray& ray) {
  const RayTriangleSetup s(ray);
  for (uint32_t i = 0; i < m.ids.size(); ++i) {
    float t, u, v;
    if (IntersectTriangle(s, m.vertices[3 * i], m.vertices[3 * i + 1], m.vertices[3 * i + 2],
                          ray.tmin, ray.tmax, &t, &u, &v))
      return true;
  }
  return false;
}

void ExpectSameHit(const Hit& expected, const Hit& got) {
  EXPECT_EQ(0, std::memcmp(&expected.t, &got.t, sizeof(float))) << expected.t << " " << got.t;
  EXPECT_EQ(expected.u, got.u);
  EXPECT_EQ(expected.v, got.v);
  EXPECT_EQ(expected.triangle_id, got.triangle_id);
  EXPECT_EQ(expected.block_id, got.block_id);
  EXPECT_EQ(expected.local_triangle, got.local_triangle);
}

// Small random triangles in the unit box, some of them repeated under other ids (coplanar
// duplicates: CloserThan's ties), ids shuffled so the smaller one is not always first.
Mesh Soup(int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> pos(0, 1), size(-0.05f, 0.05f);
  std::vector<uint32_t> ids(static_cast<size_t>(n) + static_cast<size_t>(n) / 10);
  for (uint32_t i = 0; i < ids.size(); ++i) ids[i] = 3 * i + 1;
  std::shuffle(ids.begin(), ids.end(), rng);
  Mesh m;
  for (int i = 0; i < n; ++i) {
    const Vec3f c{pos(rng), pos(rng), pos(rng)};
    const Vec3f a = c + Vec3f{size(rng), size(rng), size(rng)};
    const Vec3f b = c + Vec3f{size(rng), size(rng), size(rng)};
    const Vec3f d = c + Vec3f{size(rng), size(rng), size(rng)};
    m.Add(a, b, d, ids[m.ids.size()]);
    if (i % 10 == 0) m.Add(a, b, d, ids[m.ids.size()]);
  }
  return m;
}

std::vector<Ray> Rays(int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> pos(-0.2f, 1.2f), dir(-1, 1);
  std::vector<Ray> rays;
  for (int i = 0; i < n; ++i) {
    Ray r;
    r.origin = {pos(rng), pos(rng), pos(rng)};
    r.direction = {dir(rng), dir(rng), dir(rng)};
    if (i % 7 == 0) r.direction[i % 3] = 0;           // parallel to a slab
    if (i % 11 == 0) r.direction = {0, 0, i % 2 ? 1.0f : -1.0f};  // along an axis
    if (i % 5 == 0) r.tmin = 0.1f;
    if (i % 13 == 0) r.tmax = 0.3f;
    rays.push_back(r);
  }
  return rays;
}

// Runs `body` on each copy of the walks (single rays and packets) this machine has: the
// baseline (SSE2 on x86-64), then AVX2 and AVX2 with AVX-512 where the CPU has them. They must
// agree with brute force alike.
template <typename Body>
void ForEachWalk(Body&& body) {
  using Isa = WideBvh::WalkIsa;
  for (Isa isa : {Isa::kBaseline, Isa::kAvx2, Isa::kAvx512}) {
    const Isa used = WideBvh::LimitWalks(isa);
    if (used != isa) continue;  // the CPU does not have it: a narrower copy was the widest
    SCOPED_TRACE(std::string(WideBvh::WalkIsaName(used)) + " walks");
    body();
  }
  WideBvh::LimitWalks(Isa::kAvx512);
}

// The walks take the widest copy the CPU has: limited to a copy, they use it or a narrower one,
// and the AVX-512 copy serves where the CPU has every instruction set it may contain, AVX2
// where it has AVX2 but not all of those.
TEST(WideBvh, WalksTakeTheWidestCopyTheCpuHas) {
  using Isa = WideBvh::WalkIsa;
  EXPECT_EQ(WideBvh::LimitWalks(Isa::kBaseline), Isa::kBaseline);
  EXPECT_LE(WideBvh::LimitWalks(Isa::kAvx2), Isa::kAvx2);
  const Isa widest = WideBvh::LimitWalks(Isa::kAvx512);
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
  const bool avx2 = __builtin_cpu_supports("avx2");
  const bool avx512 = avx2 && __builtin_cpu_supports("bmi") && __builtin_cpu_supports("bmi2") &&
                      __builtin_cpu_supports("fma") && __builtin_cpu_supports("avx512f") &&
                      __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512dq") &&
                      __builtin_cpu_supports("avx512bw");
  EXPECT_EQ(widest, avx512 ? Isa::kAvx512 : (avx2 ? Isa::kAvx2 : Isa::kBaseline));
  std::printf("walks here: %s\n", WideBvh::WalkIsaName(widest));
#else
  EXPECT_EQ(widest, Isa::kBaseline);  // clang or not x86-64: the baseline copy alone
#endif
}

TEST(WideBvh, RandomSoupMatchesBruteForceBitForBit) {
  const Mesh m = Soup(3000, 7);
  const WideBvh bvh(m.vertices, m.ids, m.origins);
  EXPECT_EQ(bvh.triangle_count(), m.ids.size());
  EXPECT_GT(bvh.node_count(), 10u);
  ForEachWalk([&] {
    int hits = 0, occluded = 0;
    for (const Ray& ray : Rays(4000, 11)) {
      Hit start;
      start.t = ray.tmax;
      const Hit expected = BruteIntersect(m, ray, start);
      Hit got = start;
      EXPECT_EQ(bvh.Intersect(ray, &got), expected.Valid());
      ExpectSameHit(expected, got);
      hits += expected.Valid();
      const bool any = BruteOccluded(m, ray);
      EXPECT_EQ(bvh.Occluded(ray), any);
      occluded += any;
    }
    // Both answers occur often enough to mean something.
    EXPECT_GT(hits, 400);
    EXPECT_LT(hits, 3600);
    EXPECT_GT(occluded, 400);
  });
}

TEST(WideBvh, EqualDistanceGoesToTheSmallerIdWhateverTheOrder) {
  ForEachWalk([] {
    for (bool smaller_first : {true, false}) {
      Mesh m;
      const Vec3f a{-1, -1, 2}, b{1, -1, 2}, c{0, 1, 2};
      m.Add(a, b, c, smaller_first ? 5 : 9);
      m.Add(a, b, c, smaller_first ? 9 : 5);
      const WideBvh bvh(m.vertices, m.ids, m.origins);
      Hit h;
      ASSERT_TRUE(bvh.Intersect(Ray{{0, 0, 0}, {0, 0, 1}}, &h));
      EXPECT_EQ(h.t, 2.0f);
      EXPECT_EQ(h.triangle_id, 5u);
      EXPECT_EQ(h.local_triangle, smaller_first ? 0u : 1u);
      EXPECT_EQ(h.block_id, smaller_first ? 1u : 8u);
    }
  });
}

TEST(WideBvh, StartsFromTheHitItIsGiven) {
  Mesh m;
  m.Add({-1, -1, 2}, {1, -1, 2}, {0, 1, 2}, 8);
  m.Add({-1, -1, 3}, {1, -1, 3}, {0, 1, 3}, 2);
  const WideBvh bvh(m.vertices, m.ids, m.origins);
  ForEachWalk([&] {
    const Ray ray{{0, 0, 0}, {0, 0, 1}};
    Hit h;
    h.t = 1.5f;  // found elsewhere, closer than both
    EXPECT_FALSE(bvh.Intersect(ray, &h));
    h.t = 2.0f;  // a tie at t = 2 with a larger id: triangle 8 wins it
    h.triangle_id = 9;
    ASSERT_TRUE(bvh.Intersect(ray, &h));
    EXPECT_EQ(h.triangle_id, 8u);
    h.triangle_id = 7;  // a tie with a smaller id keeps it
    EXPECT_FALSE(bvh.Intersect(ray, &h));
    EXPECT_FALSE(bvh.Occluded(Ray{{0, 0, 0}, {0, 0, 1}, 0, 2.0f}));  // open at tmax
    EXPECT_TRUE(bvh.Occluded(Ray{{0, 0, 0}, {0, 0, 1}, 0, 2.5f}));
    EXPECT_FALSE(bvh.Occluded(Ray{{0, 0, 0}, {0, 0, 1}, 3.0f, kInf}));  // open at tmin
  });
}

TEST(WideBvh, EmptyAndSingleTriangleMeshes) {
  const WideBvh empty(std::vector<Vec3f>{}, std::vector<uint32_t>{}, std::vector<TriangleOrigin>{});
  Mesh m;
  m.Add({-1, -1, 2}, {1, -1, 2}, {0, 1, 2}, 4);
  const WideBvh one(m.vertices, m.ids, m.origins);
  ForEachWalk([&] {
    Hit h;
    EXPECT_FALSE(empty.Intersect(Ray{{0, 0, 0}, {0, 0, 1}}, &h));
    EXPECT_FALSE(empty.Occluded(Ray{{0, 0, 0}, {0, 0, 1}}));
    ASSERT_TRUE(one.Intersect(Ray{{0, 0, 0}, {0, 0, 1}}, &h));
    EXPECT_EQ(h.triangle_id, 4u);
    EXPECT_EQ(h.block_id, 1u);
    EXPECT_EQ(h.local_triangle, 0u);
    EXPECT_FALSE(one.Occluded(Ray{{5, 0, 0}, {0, 0, 1}}));
  });
}

// Found on the conference room: IntersectTriangle, deciding in float relative to a far
// origin, accepts triangle 76502 at t = 0.999999285, while the tight box of its leaf is entered
// at t = 1 as computed. A farther hit found first (74017, at 0.999999464) must not prune that
// leaf.
TEST(WideBvh, AHitJustOutsideItsBoxIsNotPruned) {
  const geometry_test::HitOutsideItsBox c = geometry_test::ConferenceRoomHitOutsideItsBox();
  Mesh m;
  for (int i = 0; i < 5; ++i) {
    const geometry_test::Triangle& t = c.triangles[i];
    m.Add(t.p[0], t.p[1], t.p[2], c.ids[i]);
  }
  const WideBvh bvh(m.vertices, m.ids, m.origins);
  const Ray ray{c.origin, c.direction};
  const Hit expected = BruteIntersect(m, ray, Hit{});
  ASSERT_EQ(expected.triangle_id, 76502u);
  ForEachWalk([&] {
    Hit got;
    ASSERT_TRUE(bvh.Intersect(ray, &got));
    ExpectSameHit(expected, got);
  });
}

// A closed, bumpy mesh far from the origin, and the same triangles as a Mesh.
geometry_test::ClosedMesh BumpyClosedMesh() {
  return geometry_test::MakeClosedMesh(geometry_test::MeshShape::kScan, 24, 1e3, 5e3);
}

Mesh MeshOf(const geometry_test::ClosedMesh& closed) {
  Mesh m;
  for (size_t i = 0; i < closed.triangles.size(); ++i) {
    const geometry_test::Triangle& t = closed.triangles[i];
    m.Add(t.p[0], t.p[1], t.p[2], static_cast<uint32_t>(i));
  }
  return m;
}

// From inside a closed, bumpy mesh every ray must hit: a box culled by rounding would let one
// escape through it. The hit is the brute-force one, bit for bit.
TEST(WideBvh, NoRayEscapesAClosedMesh) {
  const geometry_test::ClosedMesh closed = BumpyClosedMesh();
  const Mesh m = MeshOf(closed);
  const WideBvh bvh(m.vertices, m.ids, m.origins);
  ForEachWalk([&] {
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> dir(-1, 1);
    for (int i = 0; i < 3000; ++i) {
      const Ray ray{closed.center, {dir(rng), dir(rng), dir(rng)}};
      Hit h;
      ASSERT_TRUE(bvh.Intersect(ray, &h)) << "ray " << i << " escaped";
      ExpectSameHit(BruteIntersect(m, ray, Hit{}), h);
      EXPECT_TRUE(bvh.Occluded(ray));
    }
  });
}

// Packets of rays through neighbouring pixels of a camera looking at the soup (the coherent
// case the packet walk is for), some lanes starting from a hit found elsewhere and some with a
// shorter or later range: every lane as brute force, bit for bit, and the mask says which lanes
// got a closer hit.
constexpr int kPacket = WideBvh::kPacketSize;  // 4 x 4 pixels
constexpr uint32_t kEveryLane = (1u << kPacket) - 1;

void ExpectPacketsMatchBruteForce(const Mesh& m, const WideBvh& bvh,
                                  const std::vector<std::vector<Ray>>& packets) {
  ForEachWalk([&] {
    for (size_t k = 0; k < packets.size(); ++k) {
      const std::vector<Ray>& rays = packets[k];
      std::vector<Hit> start(rays.size()), got(rays.size());
      for (size_t i = 0; i < rays.size(); ++i) {
        start[i].t = rays[i].tmax;
        if ((k + i) % 9 == 4) {  // a hit found elsewhere, halfway to the nearest
          const Hit near = BruteIntersect(m, rays[i], start[i]);
          if (near.Valid()) start[i] = {near.t * 0.5f + rays[i].tmin * 0.5f, 0, 0, 1u << 30, 0, 0};
        }
        got[i] = start[i];
      }
      const uint32_t found = bvh.IntersectPacket(rays, got);
      uint32_t occluded = bvh.OccludedPacket(rays);
      for (size_t i = 0; i < rays.size(); ++i) {
        SCOPED_TRACE(testing::Message() << "packet " << k << " lane " << i);
        const Hit expected = BruteIntersect(m, rays[i], start[i]);
        ExpectSameHit(expected, got[i]);
        EXPECT_EQ((found >> i) & 1, expected.triangle_id != start[i].triangle_id ? 1u : 0u);
        EXPECT_EQ((occluded >> i) & 1, BruteOccluded(m, rays[i]) ? 1u : 0u);
      }
      EXPECT_EQ(found >> rays.size(), 0u);
      EXPECT_EQ(occluded >> rays.size(), 0u);
    }
  });
}

std::vector<std::vector<Ray>> CameraPackets(Vec3f eye, int width, int height, uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<std::vector<Ray>> packets;
  for (int by = 0; by < height; by += 4) {
    for (int bx = 0; bx < width; bx += 4) {
      std::vector<Ray> rays;
      const int lanes = 1 + static_cast<int>(rng() % kPacket);  // partly filled packets too
      for (int j = 0; j < lanes; ++j) {
        const float x = (static_cast<float>(bx + j % 4) + 0.5f) / static_cast<float>(width);
        const float y = (static_cast<float>(by + j / 4) + 0.5f) / static_cast<float>(height);
        Ray r{eye, Vec3f{x, y, 0.5f} - eye};
        if (rng() % 5 == 0) r.tmin = 0.9f;
        if (rng() % 7 == 0) r.tmax = 1.2f;
        rays.push_back(r);
      }
      packets.push_back(rays);
    }
  }
  return packets;
}

TEST(WideBvh, PacketsOfCameraRaysMatchBruteForceBitForBit) {
  const Mesh m = Soup(3000, 5);
  const WideBvh bvh(m.vertices, m.ids, m.origins);
  // Looking along +z from in front of the box, then from a corner (other shear axes and signs).
  ExpectPacketsMatchBruteForce(m, bvh, CameraPackets({0.5f, 0.5f, -1.0f}, 64, 48, 1));
  ExpectPacketsMatchBruteForce(m, bvh, CameraPackets({1.6f, 1.7f, -0.8f}, 48, 32, 2));
}

// Camera packets whose rays share the eye bit for bit take a walk that moves each corner to it
// once for all lanes; here one lane of each packet starts a little off the eye (still close
// enough to share the packet), in either register of lanes, or at -0 where the eye has +0.
// Every lane must still come out as brute force from its own origin.
TEST(WideBvh, PacketsWithOneLaneFromElsewhereMatchBruteForceBitForBit) {
  const Mesh m = Soup(3000, 10);
  const WideBvh bvh(m.vertices, m.ids, m.origins);
  std::vector<std::vector<Ray>> packets = CameraPackets({0.0f, 0.5f, -1.0f}, 64, 48, 4);
  for (size_t k = 0; k < packets.size(); ++k) {
    std::vector<Ray>& rays = packets[k];
    Ray& r = rays[(k * 7) % rays.size()];
    if (k % 3 == 0) {
      r.origin.x = -0.0f;
    } else {
      r.origin = r.origin + Vec3f{0.003f, -0.002f, 0.001f};
    }
  }
  ExpectPacketsMatchBruteForce(m, bvh, packets);
}

// Shadow-like packets: nearby origins on a patch, towards one point (a light).
TEST(WideBvh, PacketsFromNearbyOriginsMatchBruteForceBitForBit) {
  const Mesh m = Soup(3000, 6);
  const WideBvh bvh(m.vertices, m.ids, m.origins);
  std::mt19937 rng(8);
  std::uniform_real_distribution<float> pos(0, 1), jitter(0, 0.01f);
  std::vector<std::vector<Ray>> packets;
  for (int k = 0; k < 600; ++k) {
    const Vec3f base{pos(rng), pos(rng), pos(rng)};
    const Vec3f light = k % 2 ? Vec3f{0.5f, 2.0f, 0.5f} : Vec3f{-1.0f, 0.3f, 1.5f};
    std::vector<Ray> rays;
    for (int i = 0; i < kPacket; ++i) {
      const Vec3f o = base + Vec3f{jitter(rng), jitter(rng), jitter(rng)};
      rays.push_back(Ray{o, light - o, 1e-4f, 1.0f - 1e-4f});
    }
    packets.push_back(rays);
  }
  ExpectPacketsMatchBruteForce(m, bvh, packets);
}

// Camera packets with hostile lanes among coherent ones: a NaN or infinite coordinate, a zero
// direction component, a direction 1e30 long. A packet's set-up reads every lane at once; these
// lanes must not widen or poison the others' bounds, and each must come out as brute force.
// The non-finite lanes take the single-ray walk, which an infinite origin or an all-NaN
// direction used to send into a node's empty child (a crash; see Node::occupied).
TEST(WideBvh, PacketsWithNonFiniteLanesMatchBruteForceBitForBit) {
  const Mesh m = Soup(3000, 9);
  const WideBvh bvh(m.vertices, m.ids, m.origins);
  const float inf = std::numeric_limits<float>::infinity(), nan = std::nanf("");
  std::vector<std::vector<Ray>> packets = CameraPackets({0.5f, 0.5f, -1.0f}, 32, 32, 3);
  for (size_t k = 0; k < packets.size(); ++k) {
    std::vector<Ray>& rays = packets[k];
    Ray& r = rays[k % rays.size()];
    switch (k % 8) {
      case 0: r.direction.y = nan; break;
      case 1: r.origin.x = inf; break;
      case 2: r.direction.z = -inf; break;
      case 3: r.direction.x = 0; break;
      case 4: r.direction = r.direction * 1e30f; break;
      case 5: r.direction = {nan, nan, nan}; break;
      case 6: r.direction = {inf, -inf, inf}; break;
      default: r.origin.z = nan; break;
    }
  }
  ExpectPacketsMatchBruteForce(m, bvh, packets);
}

// Rays that cannot share a walk (other direction signs or shear axes, directions parallel to
// a slab, far-apart origins or directions) in one call: each as brute force.
TEST(WideBvh, PacketsOfUnrelatedRaysMatchBruteForceBitForBit) {
  const Mesh m = Soup(3000, 7);
  const WideBvh bvh(m.vertices, m.ids, m.origins);
  const std::vector<Ray> rays = Rays(4000, 12);
  std::vector<std::vector<Ray>> packets;
  for (size_t i = 0; i < rays.size(); i += kPacket)
    packets.emplace_back(rays.begin() + static_cast<ptrdiff_t>(i),
                         rays.begin() + static_cast<ptrdiff_t>(std::min(rays.size(), i + kPacket)));
  ExpectPacketsMatchBruteForce(m, bvh, packets);
  Hit none[1];
  EXPECT_EQ(bvh.IntersectPacket({}, none), 0u);
  EXPECT_EQ(bvh.OccludedPacket({}), 0u);
}

// Packets aimed exactly at the shared edges and corners of a grid of triangles, where
// IntersectTriangle finds an edge value of zero and decides in double: every lane must hit
// (the test is watertight) and equal brute force. The coordinates make the sheared values
// exact: the eye is 32 from the plane, the targets on a grid of halves.
TEST(WideBvh, PacketsThroughSharedEdgesAndCornersHit) {
  Mesh m;
  uint32_t id = 0;
  for (int y = -4; y < 4; ++y) {
    for (int x = -4; x < 4; ++x) {
      const auto fx = static_cast<float>(x), fy = static_cast<float>(y);
      m.Add({fx, fy, 0}, {fx + 1, fy, 0}, {fx + 1, fy + 1, 0}, id++);
      m.Add({fx, fy, 0}, {fx + 1, fy + 1, 0}, {fx, fy + 1, 0}, id++);
    }
  }
  const WideBvh bvh(m.vertices, m.ids, m.origins);
  const Vec3f eye{0, 0, -32};
  std::vector<std::vector<Ray>> packets;
  for (int by = -6; by < 6; by += 4) {
    for (int bx = -6; bx < 6; bx += 4) {
      std::vector<Ray> rays;
      for (int j = 0; j < kPacket; ++j) {
        const Vec3f target{0.5f * static_cast<float>(bx + j % 4), 0.5f * static_cast<float>(by + j / 4), 0};
        rays.push_back(Ray{eye, target - eye});
      }
      packets.push_back(rays);
    }
  }
  ExpectPacketsMatchBruteForce(m, bvh, packets);
  ForEachWalk([&] {
    for (const std::vector<Ray>& rays : packets) {
      Hit hits[WideBvh::kPacketSize];
      EXPECT_EQ(bvh.IntersectPacket(rays, hits), kEveryLane);
    }
  });
}

// From inside a closed mesh, packets of close directions: no lane may escape.
TEST(WideBvh, NoPacketRayEscapesAClosedMesh) {
  const geometry_test::ClosedMesh closed = BumpyClosedMesh();
  const Mesh m = MeshOf(closed);
  const WideBvh bvh(m.vertices, m.ids, m.origins);
  std::mt19937 rng(4);
  std::uniform_real_distribution<float> dir(-1, 1), near(-0.02f, 0.02f);
  std::vector<std::array<Ray, WideBvh::kPacketSize>> packets(400);
  for (auto& rays : packets) {
    const Vec3f d{dir(rng), dir(rng), dir(rng)};
    for (Ray& r : rays) r = Ray{closed.center, d + Vec3f{near(rng), near(rng), near(rng)}};
  }
  ForEachWalk([&] {
    for (size_t k = 0; k < packets.size(); ++k) {
      Hit hits[WideBvh::kPacketSize];
      EXPECT_EQ(bvh.IntersectPacket(packets[k], hits), kEveryLane) << "packet " << k;
      EXPECT_EQ(bvh.OccludedPacket(packets[k]), kEveryLane) << "packet " << k;
      for (int i = 0; i < WideBvh::kPacketSize; ++i)
        ExpectSameHit(BruteIntersect(m, packets[k][static_cast<size_t>(i)], Hit{}), hits[i]);
    }
  });
}

}  // namespace
}  // namespace raystack
