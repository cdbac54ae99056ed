// Writes the binary seeds of the block, wire and store fuzz targets (the text formats' seeds are
// written by hand): run once, its output is committed in tests/fuzz/corpus/. Usage:
//   write_seeds CORPUS_DIR
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "common/geometry/bounds.h"
#include "common/render/sample_result.h"
#include "common/store/block_codec.h"
#include "common/store/block_encoder.h"
#include "common/wire/message.h"
#include "tools/prep/convert.h"

namespace {

using namespace raystack;

void Write(const std::string& path, const std::vector<uint8_t>& bytes) {
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f || std::fwrite(bytes.data(), 1, bytes.size(), f) != bytes.size() || std::fclose(f)) {
    std::fprintf(stderr, "cannot write %s\n", path.c_str());
    std::exit(1);
  }
}

// A few triangles of a small grid, as the converter would hand a leaf.
std::vector<uint8_t> RawBlock(int cells, bool attributes) {
  std::vector<store::PackedTriangle> tris;
  std::vector<store::TriangleAttributes> attrs;
  for (int i = 0; i < cells; ++i) {
    for (int j = 0; j < cells; ++j) {
      const float x = float(i), y = float(j);
      const uint32_t flags = attributes ? store::PackedTriangle::kHasNormals : 0;
      tris.push_back({{{x, y, 0}, {x + 1, y, 0}, {x, y + 1, 0.5f}}, uint32_t(tris.size()),
                      (attributes ? 1u : store::kNoMaterial) | flags});
      tris.push_back({{{x + 1, y, 0}, {x + 1, y + 1, 0.5f}, {x, y + 1, 0.5f}},
                      uint32_t(tris.size()), (attributes ? 2u : store::kNoMaterial) | flags});
    }
  }
  std::vector<uint32_t> refs;
  std::vector<Bounds3f> bounds;
  for (const auto& t : tris) {
    Bounds3f b;
    for (const Vec3f& p : t.p) b.Extend(p);
    bounds.push_back(b);
    refs.push_back(uint32_t(refs.size()));
    if (attributes) attrs.push_back({{{0, 0, 1}, {0, 0, 1}, {0, 0, 1}}, {{0, 0}, {1, 0}, {0, 1}}});
  }
  store::EncodeInput in{tris, attrs, refs, bounds, {{0, 0, 0}, {float(cells), float(cells), 1}}};
  store::BlockEncoder encoder;
  std::vector<uint8_t> raw;
  encoder.Encode(in, &raw);
  return raw;
}

std::vector<uint8_t> ReadBody(const std::string& path) {
  FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) {
    std::fprintf(stderr, "cannot read %s\n", path.c_str());
    std::exit(1);
  }
  std::vector<uint8_t> bytes;
  uint8_t buffer[4096];
  for (size_t n; (n = std::fread(buffer, 1, sizeof buffer, f)) > 0;) bytes.insert(bytes.end(), buffer, buffer + n);
  std::fclose(f);
  return {bytes.begin() + std::min<size_t>(bytes.size(), 32), bytes.end()};  // after the FileHeader
}

// A store converted from a generated sphere, in store_fuzz's input form: the lengths of the
// index and octree bodies, then the index, octree and blocks bodies.
std::vector<uint8_t> StoreSeed(const std::string& dir, const std::string& model,
                               uint32_t target_block_bytes) {
  prep::ConvertOptions o;
  o.generate = model;
  o.output = dir + "/seed-store";
  o.quiet = true;
  o.threads = 1;
  o.target_block_bytes = target_block_bytes;
  o.max_block_bytes = 4 * target_block_bytes;
  if (Expected<prep::ConvertReport> r = prep::Convert(o); !r.ok()) {
    std::fprintf(stderr, "%s\n", r.status().message().c_str());
    std::exit(1);
  }
  const std::vector<uint8_t> index = ReadBody(o.output + "/index.bin");
  const std::vector<uint8_t> octree = ReadBody(o.output + "/octree.bin");
  const std::vector<uint8_t> blocks = ReadBody(o.output + "/blocks.bin");
  std::vector<uint8_t> out(8);
  const uint32_t lengths[2] = {uint32_t(index.size()), uint32_t(octree.size())};
  std::memcpy(out.data(), lengths, 8);
  for (const auto* part : {&index, &octree, &blocks}) out.insert(out.end(), part->begin(), part->end());
  for (const char* name : {"index.bin", "octree.bin", "blocks.bin"}) std::remove((o.output + "/" + name).c_str());
  std::remove(o.output.c_str());
  return out;
}

std::vector<uint8_t> Prefixed(uint32_t raw_bytes, uint8_t mode, const std::vector<uint8_t>& b) {
  std::vector<uint8_t> out(5);
  std::memcpy(out.data(), &raw_bytes, 4);
  out[4] = mode;
  out.insert(out.end(), b.begin(), b.end());
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: write_seeds CORPUS_DIR\n");
    return 2;
  }
  const std::string dir = argv[1];
  int n = 0;
  for (auto [cells, attributes] : {std::pair{2, false}, std::pair{6, true}}) {
    const std::vector<uint8_t> raw = RawBlock(cells, attributes);
    std::vector<uint8_t> stored;
    store::EncodeBlock(raw, &stored, true);
    Write(dir + "/block/shuffled-" + std::to_string(n), Prefixed(uint32_t(raw.size()), 2, stored));
    store::EncodeBlock(raw, &stored, false);
    Write(dir + "/block/plain-" + std::to_string(n), Prefixed(uint32_t(raw.size()), 0, stored));
    Write(dir + "/block/raw-" + std::to_string(n), Prefixed(0, 1, raw));
    ++n;
  }

  // Several blocks in a few octree levels, and a single-block store.
  Write(dir + "/store/sphere-300", StoreSeed(dir, "sphere:300", 2048));
  Write(dir + "/store/sphere-40", StoreSeed(dir, "sphere:40", 32768));

  Write(dir + "/wire/hello", wire::Encode(1, wire::Hello{4, 0, 0, 0, {}, {}}));
  Write(dir + "/wire/tile_request", wire::Encode(1, wire::TileRequest{0, 2}));
  wire::TileAssign assign{};
  assign.thread = 1;
  assign.x1 = assign.y1 = 32;
  assign.sample_end = 4;
  assign.rank_end = 64;
  Write(dir + "/wire/tile_assign", wire::Encode(1, assign));
  Write(dir + "/wire/heartbeat", wire::Encode(1, wire::Heartbeat{7, 0}));
  Write(dir + "/wire/rank_lost", wire::Encode(1, wire::RankLost{2, 1}));
  wire::FrameDone done{};
  done.samples = 1024;
  done.seconds = 1.5;
  Write(dir + "/wire/frame_done", wire::Encode(1, done));
  Write(dir + "/wire/shutdown", wire::Encode(1, wire::Shutdown{0, 0}));
  const std::vector<wire::BlockRun> runs = {{10, 2}, {17, 1}};
  Write(dir + "/wire/block_request", wire::EncodeBlockRequest(1, 3, runs));
  const std::vector<uint8_t> stored_bytes(40, 0xab);
  Write(dir + "/wire/block_data",
        wire::EncodeBlockData(1, wire::BlockDataHeader{3, 2, 0, 0}, stored_bytes));
  Write(dir + "/wire/error", wire::EncodeError(1, "block 12 is malformed: bad magic"));
  std::vector<render::SampleResult> samples(3);  // two kinds: sample 0 carries primary layers
  samples[1].sample = 1;
  samples[2].sample = 2;
  samples[2].hit = 1;
  Write(dir + "/wire/pixel_batch", wire::EncodePixelBatch(1, 0, samples));
  return 0;
}
