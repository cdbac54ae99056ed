// libFuzzer target: opening a block store whose index.bin and octree.bin are hostile but
// correctly sealed (right magic, version, sizes and checksums, so the fuzzer's bytes reach the
// validation behind them), then everything a renderer does with a store that opened: the
// in-core tracer's octree walk, the ray stack's resumable BlockWalk, and the loader's reads of
// neighbouring blocks as one run. Input:
//   bytes 0-3   length of index.bin's body (little-endian, taken modulo what is left)
//   bytes 4-7   length of octree.bin's body (the same)
//   then the index body, the octree body, and the rest is blocks.bin's body.
// Checks beyond "no crash": every error names its file; walks name existing blocks, visit
// each at most once and end; a run's blocks lie inside the bytes read for it.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "common/base/check.h"
#include "common/store/block_codec.h"
#include "common/store/format.h"
#include "common/store/store_reader.h"
#include "common/store/store_bvh.h"
#include "common/store/store_tracer.h"
#include "slave/block_source.h"
#include "slave/block_walk.h"
#include "tests/fuzz/fuzz_folder.h"
#include "tests/fuzz/fuzz_quiet.h"

namespace {

using namespace raystack;
using namespace raystack::store;

constexpr uint32_t kMaxBlocksRead = 64;  // bounds one input's work

void WriteSealed(const std::string& path, const char (&magic)[8], std::span<const uint8_t> body,
                 bool blocks) {
  FileHeader h{};
  std::memcpy(h.magic, magic, sizeof h.magic);
  h.version = kFormatVersion;
  h.header_bytes = sizeof h;
  h.body_bytes = body.size();
  h.body_checksum = blocks ? 0 : Checksum(body);
  fuzz::WriteFile(path, {reinterpret_cast<const uint8_t*>(&h), sizeof h}, body);
}

uint32_t Length(const uint8_t* p, size_t left) {
  uint32_t n;
  std::memcpy(&n, p, 4);
  return left == 0 ? 0 : static_cast<uint32_t>(n % (left + 1));
}

void ExpectNamesStore(const Status& s, const std::string& dir) {
  if (!s.ok()) CHECK(s.message().find(dir) != std::string::npos);
}

// Rays from outside the root cell towards points inside it, and one axis-parallel ray.
std::vector<Ray> Rays(const StoreReader& store) {
  const Bounds3f cell = store.root_cell();
  const Vec3f c = cell.Center(), d = cell.upper - cell.lower;
  std::vector<Ray> rays;
  const Vec3f targets[] = {c, c + d * 0.25f, c - Vec3f{d.x, 0, d.z} * 0.3f};
  const Vec3f origins[] = {c - d * 1.5f, c + Vec3f{d.x * 2, d.y * 0.1f, -d.z}, c + Vec3f{0, 0, d.z * 3}};
  for (const Vec3f& o : origins)
    for (const Vec3f& t : targets) rays.push_back({o, t - o});
  rays.push_back({c - Vec3f{d.x * 2, 0, 0}, {1, 0, 0}});
  return rays;
}

// The ray stack's walk: blocks in order, each once, ending.
void WalkLikeTheRayStack(const StoreReader& store, const std::vector<Ray>& rays) {
  const slave::BlockWalk walk(store.octree(), store.blocks());
  const uint32_t count = static_cast<uint32_t>(store.blocks().size());
  std::vector<uint8_t> seen(count);
  for (const Ray& ray : rays) {
    std::fill(seen.begin(), seen.end(), 0);
    uint32_t steps = 0;
    for (uint32_t b = walk.First(ray); b != kInvalidId; b = walk.Next(ray, b)) {
      CHECK(b < count);
      CHECK(!seen[b]);
      seen[b] = 1;
      CHECK(++steps <= count);
      (void)walk.DoneAfter(ray, b);
    }
  }
}

// The in-core tracer: loads blocks on demand (hostile blocks.bin bytes end in errors).
void TraceInCore(const StoreReader& store, const std::vector<Ray>& rays) {
  StoreTracer tracer(store);
  for (const Ray& ray : rays) {
    Expected<Hit> hit = tracer.Intersect(ray);
    ExpectNamesStore(hit.status(), store.dir());
    if (hit.ok() && hit->Valid()) CHECK(hit->block_id < store.blocks().size());
    ExpectNamesStore(tracer.Occluded(ray).status(), store.dir());
  }
}

// --mode bvh: every block that decodes, in one tree. A hit names a block that holds its
// triangle. (Hits are not compared with StoreTracer's: a hostile store may give one triangle id
// different vertices in two blocks.)
void TraceOneBvh(const StoreReader& store, const std::vector<Ray>& rays) {
  const uint32_t count = std::min<uint32_t>(static_cast<uint32_t>(store.blocks().size()), kMaxBlocksRead);
  std::vector<AlignedBuffer> raw(count);
  std::vector<BlockView> views;
  std::vector<uint8_t> stored;
  AlignedBuffer scratch;
  for (uint32_t id = 0; id < count; ++id) {
    Expected<BlockView> v = store.Load(id, &stored, &scratch, &raw[id]);
    ExpectNamesStore(v.status(), store.dir());
    if (!v.ok()) return;  // the engine's preload ends with this error
    views.push_back(*v);
  }
  const StoreBvh bvh(views);
  for (const Ray& ray : rays) {
    const Hit hit = bvh.Intersect(ray);
    if (hit.Valid()) {
      CHECK(hit.block_id < views.size());
      CHECK(hit.local_triangle < views[hit.block_id].triangle_count());
      CHECK(views[hit.block_id].TriangleId(hit.local_triangle) == hit.triangle_id);
    }
    (void)bvh.Occluded(ray);
  }
  // Packets give every lane the single-ray answer, whatever the geometry and on every walk
  // (SSE2, and AVX2 and AVX2 with AVX-512 where the build and the CPU have them; the clang
  // fuzzing build has SSE2 only):
  // the rays above kPacketSize at a time (mostly split apart), and kPacketSize close to the first
  // one (walked together).
  std::vector<Ray> packets = rays;
  for (int i = 0; i < WideBvh::kPacketSize && !rays.empty(); ++i) {
    const float spread = 0.004f * Length(rays[0].direction);
    packets.push_back({rays[0].origin, rays[0].direction + Vec3f{static_cast<float>(i % 4) * spread,
                                                                 static_cast<float>(i / 4) * spread, 0}});
  }
  using Isa = WideBvh::WalkIsa;
  for (Isa isa : {Isa::kBaseline, Isa::kAvx2, Isa::kAvx512}) {
    if (WideBvh::LimitWalks(isa) != isa) continue;  // the CPU (or clang) has no such copy
    for (size_t i = 0; i < packets.size(); i += WideBvh::kPacketSize) {
      const size_t n = std::min(packets.size() - i, size_t{WideBvh::kPacketSize});
      const std::span<const Ray> packet(packets.data() + i, n);
      Hit hits[WideBvh::kPacketSize];
      for (size_t j = 0; j < n; ++j) hits[j].t = packet[j].tmax;
      const uint32_t found = bvh.IntersectPacket(packet, {hits, n});
      const uint32_t occluded = bvh.OccludedPacket(packet);
      for (size_t j = 0; j < n; ++j) {
        const Hit one = bvh.Intersect(packet[j]);
        CHECK(((found >> j) & 1) == (one.Valid() ? 1u : 0u));
        if (one.Valid()) {
          CHECK(std::memcmp(&one.t, &hits[j].t, sizeof(float)) == 0);
          CHECK(one.u == hits[j].u && one.v == hits[j].v);
          CHECK(one.triangle_id == hits[j].triangle_id && one.block_id == hits[j].block_id &&
                one.local_triangle == hits[j].local_triangle);
        }
        CHECK(((occluded >> j) & 1) == (bvh.Occluded(packet[j]) ? 1u : 0u));
      }
    }
  }
  WideBvh::LimitWalks(Isa::kAvx512);
}

// The loader's reads: neighbouring ids as one run, each block found at its offset from the
// run's first, then decoded.
void ReadLikeTheLoader(const StoreReader& store) {
  slave::DiskBlockSource source(store, {});
  std::vector<uint8_t> bytes;
  AlignedBuffer scratch, raw;
  const uint32_t count = static_cast<uint32_t>(store.blocks().size());
  for (uint32_t first = 0; first < count && first < kMaxBlocksRead; first += 2) {
    const uint32_t ids[2] = {first, first + 1};
    const std::span<const uint32_t> run(ids, first + 1 < count ? 2 : 1);
    const Status read = source.ReadRun(run, &bytes);
    ExpectNamesStore(read, store.dir());
    if (!read.ok()) continue;
    const uint64_t base = store.blocks()[first].offset;
    for (uint32_t id : run) {
      const BlockEntry& e = store.blocks()[id];
      CHECK(e.offset >= base && e.offset - base + e.stored_bytes <= bytes.size());
      const std::span<const uint8_t> stored(bytes.data() + (e.offset - base), e.stored_bytes);
      ExpectNamesStore(store.Decode(id, stored, &scratch, &raw).status(), store.dir());
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 8) return 0;
  const uint8_t* p = data + 8;
  size_t left = size - 8;
  const uint32_t index_bytes = Length(data, left);
  const std::span<const uint8_t> index(p, index_bytes);
  p += index_bytes;
  left -= index_bytes;
  const uint32_t octree_bytes = Length(data + 4, left);
  const std::span<const uint8_t> octree(p, octree_bytes);
  const std::span<const uint8_t> blocks(p + octree_bytes, left - octree_bytes);

  const std::string& dir = fuzz::Folder();
  WriteSealed(dir + "/" + kIndexFile, kIndexMagic, index, false);
  WriteSealed(dir + "/" + kOctreeFile, kOctreeMagic, octree, false);
  WriteSealed(dir + "/" + kBlocksFile, kBlocksMagic, blocks, true);

  Expected<std::unique_ptr<StoreReader>> opened = StoreReader::Open(dir);
  if (!opened.ok()) {
    ExpectNamesStore(opened.status(), dir);
    return 0;
  }
  const StoreReader& store = **opened;
  const std::vector<Ray> rays = Rays(store);
  WalkLikeTheRayStack(store, rays);
  TraceInCore(store, rays);
  TraceOneBvh(store, rays);
  ReadLikeTheLoader(store);
  return 0;
}
