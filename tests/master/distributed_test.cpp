// A master and N slaves as threads of one process (the in-process transport): the image equals
// the one-process image bit for bit, for Whitted and for seeded path tracing, over several
// frames with warm caches; every tile is rendered once; a malformed message, another protocol
// version or a slave's failure ends the frame with an error naming the rank, never a hang.

#include <gtest/gtest.h>

#include <set>
#include <tuple>
#include <thread>
#include <vector>

#include "common/transport/transport.h"
#include "common/wire/message.h"
#include "master/master_node.h"
#include "master/tile_scheduler.h"
#include "slave/peer_blocks.h"
#include "slave/slave_node.h"
#include "tests/slave/render_fixture.h"

namespace raystack::testing {
namespace {

using slave::EngineOptions;
using slave::TraceMode;

render::Scene TestScene(const store::StoreReader& store, render::IntegratorType type) {
  render::Scene scene;
  scene.cameras.push_back(FramingCamera(store, 80, 60));
  render::CameraDesc second = scene.cameras[0];  // a second frame: zoomed in
  second.fov_y_deg = 25;
  scene.cameras.push_back(second);
  const Bounds3f b = store.model_bounds();
  scene.lights.push_back({b.upper + (b.upper - b.lower) * 0.5f, {40, 40, 40}});
  scene.background = {0.1f, 0.1f, 0.2f};
  scene.integrator.type = type;
  scene.integrator.spp = type == render::IntegratorType::kPath ? 2 : 1;
  scene.integrator.max_depth = type == render::IntegratorType::kPath ? 5 : 3;
  scene.integrator.seed = 11;
  return scene;
}

EngineOptions Options(const store::StoreReader& store) {
  EngineOptions o;
  o.threads = 2;
  uint64_t largest = 0;
  for (const auto& e : store.blocks()) largest = std::max<uint64_t>(largest, e.raw_bytes);
  o.cache_bytes = 6 * ((largest + 63) & ~uint64_t{63});  // far smaller than the store
  o.result_batch = 100;
  return o;
}

// The job with `slaves` slave threads; returns each frame's image (or the master's error).
struct JobOutcome {
  Status master;
  std::vector<Status> slaves;
  std::vector<uint64_t> disk_reads, owned_blocks;  // per slave, with --blocks rem
  std::vector<image::ImageLayers> frames;
  std::vector<master::FrameFigures> figures;
  std::vector<std::vector<std::vector<render::Tile>>> assigned;  // per frame, per slave
};

JobOutcome RunJob(const store::StoreReader& store, const render::Scene& scene, int slaves,
                  bool rem = false, int tile = 8) {
  JobOutcome out;
  transport::InProcessHub hub(slaves + 1);
  out.slaves.resize(static_cast<size_t>(slaves));
  out.disk_reads.resize(static_cast<size_t>(slaves));
  out.owned_blocks.resize(static_cast<size_t>(slaves));
  std::vector<std::thread> threads;
  for (int r = 1; r <= slaves; ++r) {
    threads.emplace_back([&, r] {
      auto net = hub.Endpoint(r);
      std::unique_ptr<slave::PeerBlocks> peers;
      if (rem) peers = std::make_unique<slave::PeerBlocks>(net.get(), store, slave::FaultOptions{});
      auto engine = slave::RenderEngine::Create(store, Options(store), peers.get());
      ASSERT_TRUE(engine.ok());
      const render::MaterialTable materials = render::MaterialTable::Build(store.materials(), scene);
      slave::SlaveNode node(net.get(), engine->get(), peers.get());
      Status& status = out.slaves[static_cast<size_t>(r - 1)];
      for (size_t f = 0; f < scene.cameras.size() && status.ok(); ++f) {
        slave::RenderStats stats;
        status = node.RunFrame(static_cast<uint32_t>(f), scene, materials,
                               render::Camera(scene.cameras[f]), &stats);
      }
      if (status.ok()) status = node.WaitForShutdown().status();
      if (peers) {
        out.disk_reads[static_cast<size_t>(r - 1)] = peers->disk_reads();
        for (uint32_t b = 0; b < store.blocks().size(); ++b)
          out.owned_blocks[static_cast<size_t>(r - 1)] +=
              slave::BlockOwner(b, static_cast<uint32_t>(store.blocks().size()), slaves) == r;
      }
    });
  }
  auto net = hub.Endpoint(0);
  master::MasterNode node(net.get());
  for (size_t f = 0; f < scene.cameras.size(); ++f) {
    const render::Camera camera(scene.cameras[f]);
    render::Film film(camera.width(), camera.height());
    master::FrameFigures figures;
    out.master = node.RunFrame(static_cast<uint32_t>(f),
                               render::HilbertTiles(camera.width(), camera.height(), tile), &film,
                               [&] { (void)node.TilesAssigned(); },  // as the preview reads it
                               &figures);
    if (!out.master.ok()) break;
    out.frames.push_back(film.Resolve());
    out.figures.push_back(figures);
    out.assigned.push_back(node.TilesAssigned());
  }
  EXPECT_TRUE(node.Shutdown(out.master.ok() ? 0 : 1));
  for (std::thread& t : threads) t.join();
  return out;
}

class DistributedImage
    : public ::testing::TestWithParam<std::tuple<render::IntegratorType, bool>> {};

// loc (every slave reads the store) and rem (blocks from their owners' memories).
TEST_P(DistributedImage, EqualsTheOneProcessImageBitForBit) {
  TestStore s = BuildGenerated("spheres:30000");
  const auto [integrator, rem] = GetParam();
  render::Scene scene = TestScene(*s.reader, integrator);
  if (integrator == render::IntegratorType::kPath) scene.default_material.type = render::MaterialType::kDiffuse;
  // The reference: one process, one engine, frame after frame.
  std::vector<image::ImageLayers> reference;
  for (size_t f = 0; f < scene.cameras.size(); ++f) {
    render::Scene one = scene;
    one.cameras = {scene.cameras[f]};
    const RenderOutcome r = Render(*s.reader, one, Options(*s.reader));
    ASSERT_TRUE(r.status.ok()) << r.status.message();
    reference.push_back(r.image);
  }
  for (int slaves : {1, 2, 4}) {
    const JobOutcome job = RunJob(*s.reader, scene, slaves, rem);
    ASSERT_TRUE(job.master.ok()) << job.master.message();
    for (const Status& st : job.slaves) ASSERT_TRUE(st.ok()) << st.message();
    if (rem) {
      // Each block is read from disk at most once in the whole job, by its owner.
      uint64_t reads = 0;
      for (int i = 0; i < slaves; ++i) {
        EXPECT_LE(job.disk_reads[i], job.owned_blocks[i]) << "slave " << i + 1;
        reads += job.disk_reads[i];
      }
      EXPECT_LE(reads, s.reader->blocks().size());
      EXPECT_GT(reads, 0u);
      if (slaves > 1) {
        uint64_t from_peers = 0;
        for (const auto& x : job.figures[0].slaves) from_peers += x.done.bytes_from_peers;
        EXPECT_GT(from_peers, 0u);
      }
    }
    ASSERT_EQ(job.frames.size(), scene.cameras.size());
    for (size_t f = 0; f < scene.cameras.size(); ++f) {
      EXPECT_TRUE(SameBits(job.frames[f].rgba, reference[f].rgba)) << slaves << " slaves, frame " << f;
      EXPECT_TRUE(SameBits(job.frames[f].z, reference[f].z)) << slaves << " slaves, frame " << f;
      EXPECT_EQ(job.frames[f].samples, reference[f].samples) << slaves << " slaves";
      // Every slave took part, and the tiles add up to the frame's.
      uint64_t tiles = 0;
      for (const master::SlaveFigures& x : job.figures[f].slaves) {
        EXPECT_GT(x.done.samples, 0u) << "rank " << x.rank;
        EXPECT_GT(x.pixel_bytes, 0u);
        tiles += x.done.tiles;
      }
      EXPECT_EQ(tiles, render::HilbertTiles(80, 60, 8).size());
      // The master's record of who was given what (the preview's tiles in flight): each
      // slave's own count, and every tile of the frame once.
      ASSERT_EQ(job.assigned[f].size(), static_cast<size_t>(slaves));
      std::set<std::tuple<int, int>> corners;
      for (int i = 0; i < slaves; ++i) {
        EXPECT_EQ(job.assigned[f][static_cast<size_t>(i)].size(), job.figures[f].slaves[static_cast<size_t>(i)].done.tiles);
        for (const render::Tile& t : job.assigned[f][static_cast<size_t>(i)])
          EXPECT_TRUE(corners.insert({t.x0, t.y0}).second) << "tile handed out twice";
      }
      EXPECT_EQ(corners.size(), tiles);
    }
  }
}

INSTANTIATE_TEST_SUITE_P(IntegratorsAndBlocks, DistributedImage,
                         ::testing::Combine(::testing::Values(render::IntegratorType::kWhitted,
                                                              render::IntegratorType::kPath),
                                            ::testing::Bool()));

TEST(TileScheduler, EveryTileOnceEachSlaveStartsInItsOwnRegion) {
  const std::vector<render::Tile> tiles = render::HilbertTiles(200, 120, 16);
  master::TileScheduler scheduler(tiles, 3);
  std::vector<std::vector<size_t>> got(3);
  render::Tile t;
  for (int round = 0; ; ++round) {
    bool any = false;
    for (int s = 0; s < 3; ++s) {
      if (s == 2 && round % 2) continue;  // slave 2 is slower: the others take over its span
      if (!scheduler.Next(s, &t)) continue;
      any = true;
      for (size_t i = 0; i < tiles.size(); ++i)
        if (tiles[i].x0 == t.x0 && tiles[i].y0 == t.y0) got[s].push_back(i);
    }
    if (!any) break;
  }
  std::vector<int> seen(tiles.size(), 0);
  for (const auto& g : got)
    for (size_t i : g) ++seen[i];
  for (size_t i = 0; i < tiles.size(); ++i) EXPECT_EQ(seen[i], 1) << "tile " << i;
  // Each slave's first tiles are consecutive on the curve (neighbours on screen).
  for (int s = 0; s < 3; ++s) {
    ASSERT_GE(got[s].size(), 3u);
    EXPECT_EQ(got[s][1], got[s][0] + 1);
    EXPECT_EQ(got[s][2], got[s][1] + 1);
  }
  EXPECT_EQ(scheduler.handed_out(), tiles.size());
}

// A fake slave that sends `bytes` to the master where a tile request should be.
Status MasterFacing(const std::vector<uint8_t>& bytes) {
  transport::InProcessHub hub(2);
  auto master_end = hub.Endpoint(0);
  auto slave_end = hub.Endpoint(1);
  EXPECT_TRUE(slave_end->Send(0, bytes).ok());
  master::MasterNode node(master_end.get());
  render::Film film(16, 16);
  master::FrameFigures figures;
  return node.RunFrame(0, render::HilbertTiles(16, 16, 8), &film, [] {}, &figures);
}

TEST(Distributed, HostileMessagesEndTheFrameNamingTheSender) {
  std::vector<uint8_t> other_version = wire::Encode(1, wire::TileRequest{0, 0});
  other_version[4] = 3;
  for (const auto& [bytes, expected] :
       std::vector<std::pair<std::vector<uint8_t>, std::string>>{
           {other_version, "rank 1: protocol version 3"},
           {std::vector<uint8_t>(40, 0xab), "rank 1: not a raystack message"},
           {wire::Encode(2, wire::TileRequest{0, 0}), "claims to come from rank 2"},
           {wire::EncodeError(1, "block 9: checksum mismatch (the block is damaged)"),
            "rank 1: block 9: checksum mismatch"},
           {wire::Encode(1, wire::TileAssign{}), "only the master sends"},
       }) {
    const Status s = MasterFacing(bytes);
    ASSERT_FALSE(s.ok()) << expected;
    EXPECT_NE(s.message().find(expected), std::string::npos) << s.message();
  }
  // A pixel outside the image is refused too.
  render::SampleResult outside{};
  outside.pixel = 16 * 16;
  const Status s = MasterFacing(wire::EncodePixelBatch(1, 0, std::span(&outside, 1)));
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("outside the 16x16 image"), std::string::npos) << s.message();
}

TEST(Distributed, ASlaveThatFailsEndsTheJobWithItsError) {
  TestStore s = BuildGenerated("spheres:20000");
  render::Scene scene = TestScene(*s.reader, render::IntegratorType::kWhitted);
  // Every slave's engine reads block data through a source that corrupts its 3rd read.
  transport::InProcessHub hub(3);
  std::vector<std::thread> threads;
  std::vector<Status> slave_status(2);
  for (int r = 1; r <= 2; ++r)
    threads.emplace_back([&, r] {
      auto net = hub.Endpoint(r);
      EngineOptions o = Options(*s.reader);
      o.faults.corrupt_read = 2;
      auto engine = slave::RenderEngine::Create(*s.reader, o);
      ASSERT_TRUE(engine.ok());
      const render::MaterialTable materials = render::MaterialTable::Build(s.reader->materials(), scene);
      slave::SlaveNode node(net.get(), engine->get());
      slave::RenderStats stats;
      slave_status[r - 1] = node.RunFrame(0, scene, materials, render::Camera(scene.cameras[0]), &stats);
      (void)node.WaitForShutdown(std::chrono::seconds(30));  // acknowledges it, once
    });
  auto net = hub.Endpoint(0);
  master::MasterNode node(net.get());
  const render::Camera camera(scene.cameras[0]);
  render::Film film(camera.width(), camera.height());
  master::FrameFigures figures;
  const Status status = node.RunFrame(0, render::HilbertTiles(camera.width(), camera.height(), 8),
                                      &film, [] {}, &figures);
  EXPECT_TRUE(node.Shutdown(1));  // every slave acknowledges, the failed one too
  for (std::thread& t : threads) t.join();
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.message().find("damaged"), std::string::npos) << status.message();
  EXPECT_EQ(status.message().rfind("rank ", 0), 0u) << status.message();
}

}  // namespace
}  // namespace raystack::testing
