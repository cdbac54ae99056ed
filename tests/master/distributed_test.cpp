// A master and N slaves as threads of one process (the in-process transport): the image equals
// the one-process image bit for bit, for Whitted and for seeded path tracing, over several
// frames with warm caches; every tile is rendered once; a malformed message, another protocol
// version or a slave's failure ends the frame with an error naming the rank, never a hang.

#include <gtest/gtest.h>

#include <cmath>

#include <limits>

#include <functional>
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
  std::vector<std::string> dropped;  // MasterNode::SlavesDropped at the end, per slave
};

// What goes wrong in a job, on purpose.
struct JobFaults {
  int damaged_rank = 0;  // this slave's 3rd block read returns a flipped byte: it fails
  int silent_rank = 0;   // this "slave" takes a tile, sends part of it (wrong values), then
                         // falls silent, as a killed process does
  master::MasterOptions master;
};

// The silent slave: asks for a tile for its thread 0, sends samples of half its pixels with
// absurd radiance (they must all be taken back out of the film), and says nothing more.
void SilentSlave(transport::Transport* net, uint32_t spp) {
  ASSERT_TRUE(net->Send(0, wire::Encode(static_cast<uint32_t>(net->rank()),
                                        wire::TileRequest{0, 0})).ok());
  for (;;) {
    Expected<std::optional<transport::Envelope>> got = net->Receive(std::chrono::seconds(30));
    ASSERT_TRUE(got.ok() && got->has_value());
    const Expected<wire::Message> m = wire::Decode((*got)->bytes, 0);
    ASSERT_TRUE(m.ok());
    if (m->type() != wire::MessageType::kTileAssign) continue;
    const wire::TileAssign a = m->tile_assign();
    ASSERT_EQ(a.none, 0u);
    std::vector<render::SampleResult> half;
    for (int y = a.y0; y < a.y1; ++y)
      for (int x = a.x0; x < (a.x0 + a.x1) / 2; ++x)
        for (uint32_t k = 0; k < spp; ++k) {
          render::SampleResult r{};
          r.pixel = static_cast<uint32_t>(y * 80 + x);
          r.sample = k;
          r.rgb[0] = r.rgb[1] = r.rgb[2] = 1000.0f;
          r.hit = 1;
          half.push_back(r);
        }
    ASSERT_TRUE(net->Send(0, wire::EncodePixelBatch(static_cast<uint32_t>(net->rank()), 0, half)).ok());
    return;
  }
}

// With `plan`, every frame is rendered as that progressive plan, and `keep_going` is the
// master's stop rule.
// `configure` may change the slaves' engine options (Options(store) otherwise).
JobOutcome RunJob(const store::StoreReader& store, const render::Scene& scene, int slaves,
                  bool rem = false, int tile = 8, const JobFaults& faults = {},
                  const render::FramePlan* plan = nullptr,
                  const std::function<bool()>& keep_going = [] { return true; },
                  const std::function<void(EngineOptions*)>& configure = {}) {
  JobOutcome out;
  transport::InProcessHub hub(slaves + 1);
  out.slaves.resize(static_cast<size_t>(slaves));
  out.disk_reads.resize(static_cast<size_t>(slaves));
  out.owned_blocks.resize(static_cast<size_t>(slaves));
  std::vector<std::thread> threads;
  for (int r = 1; r <= slaves; ++r) {
    threads.emplace_back([&, r] {
      auto net = hub.Endpoint(r);
      if (r == faults.silent_rank) return SilentSlave(net.get(), static_cast<uint32_t>(scene.integrator.spp));
      std::unique_ptr<slave::PeerBlocks> peers;
      if (rem) peers = std::make_unique<slave::PeerBlocks>(net.get(), store, slave::FaultOptions{});
      EngineOptions options = Options(store);
      if (configure) configure(&options);
      if (r == faults.damaged_rank) options.faults.corrupt_read = 2;
      auto engine = slave::RenderEngine::Create(store, options, peers.get());
      ASSERT_TRUE(engine.ok());
      const render::MaterialTable materials = render::MaterialTable::Build(store.materials(), scene);
      slave::SlaveNode node(net.get(), engine->get(), peers.get());
      Status& status = out.slaves[static_cast<size_t>(r - 1)];
      for (size_t f = 0; f < scene.cameras.size() && status.ok(); ++f) {
        slave::RenderStats stats;
        status = node.RunFrame(static_cast<uint32_t>(f), scene, materials,
                               render::Camera(scene.cameras[f]), &stats);
      }
      // A failed slave, too, waits for the end of the job (and acknowledges it).
      const Status end = node.WaitForShutdown().status();
      if (status.ok()) status = end;
      if (peers) {
        out.disk_reads[static_cast<size_t>(r - 1)] = peers->disk_reads();
        for (uint32_t b = 0; b < store.blocks().size(); ++b)
          out.owned_blocks[static_cast<size_t>(r - 1)] +=
              slave::BlockOwner(b, static_cast<uint32_t>(store.blocks().size()), slaves) == r;
      }
    });
  }
  auto net = hub.Endpoint(0);
  master::MasterNode node(net.get(), faults.master);
  for (size_t f = 0; f < scene.cameras.size(); ++f) {
    const render::Camera camera(scene.cameras[f]);
    render::Film film(camera.width(), camera.height());
    master::FrameFigures figures;
    out.master = plan ? node.RunFrame(static_cast<uint32_t>(f), *plan, &film, keep_going, &figures)
                      : node.RunFrame(static_cast<uint32_t>(f),
                                      render::HilbertTiles(camera.width(), camera.height(), tile),
                                      static_cast<uint32_t>(scene.integrator.spp), &film,
                                      [&] { (void)node.TilesAssigned(); },  // as the preview reads it
                                      &figures);
    if (!out.master.ok()) break;
    out.frames.push_back(film.Resolve());
    out.figures.push_back(figures);
    out.assigned.push_back(node.TilesAssigned());
  }
  out.dropped = node.SlavesDropped();
  EXPECT_TRUE(node.Shutdown(out.master.ok() ? 0 : 1));
  for (std::thread& t : threads) t.join();
  return out;
}

// The reference: one process, one engine, frame after frame.
std::vector<image::ImageLayers> ReferenceFrames(const store::StoreReader& store,
                                                const render::Scene& scene) {
  std::vector<image::ImageLayers> reference;
  for (size_t f = 0; f < scene.cameras.size(); ++f) {
    render::Scene one = scene;
    one.cameras = {scene.cameras[f]};
    const RenderOutcome r = Render(store, one, Options(store));
    EXPECT_TRUE(r.status.ok()) << r.status.message();
    reference.push_back(r.image);
  }
  return reference;
}

class DistributedImage
    : public ::testing::TestWithParam<std::tuple<render::IntegratorType, bool>> {};

// loc (every slave reads the store) and rem (blocks from their owners' memories).
TEST_P(DistributedImage, EqualsTheOneProcessImageBitForBit) {
  TestStore s = BuildGenerated("spheres:30000");
  const auto [integrator, rem] = GetParam();
  render::Scene scene = TestScene(*s.reader, integrator);
  if (integrator == render::IntegratorType::kPath) scene.default_material.type = render::MaterialType::kDiffuse;
  const std::vector<image::ImageLayers> reference = ReferenceFrames(*s.reader, scene);
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
      // The tiles add up to the frame's. (Not every slave need take part: on a loaded
      // machine one may find every tile taken before it asks.)
      uint64_t tiles = 0, slaves_with_tiles = 0;
      for (const master::SlaveFigures& x : job.figures[f].slaves) {
        EXPECT_EQ(x.done.samples > 0, x.pixel_bytes > 0) << "rank " << x.rank;
        slaves_with_tiles += x.done.tiles > 0;
        tiles += x.done.tiles;
      }
      EXPECT_GE(slaves_with_tiles, 1u);
      EXPECT_EQ(tiles, render::HilbertTiles(80, 60, 8).size());
      // Utilisation is the slaves' own busy time over the thread time the frame offered.
      double busy = 0, offered = 0;
      for (const master::SlaveFigures& x : job.figures[f].slaves) {
        if (x.done.tiles > 0) {
          EXPECT_GT(x.done.busy_seconds, 0.0) << "rank " << x.rank;
          // CPU time: the process's clock over the frame holds its ray threads' own.
          EXPECT_GT(x.done.ray_cpu_seconds, 0.0) << "rank " << x.rank;
          EXPECT_GE(x.done.process_cpu_seconds + 1e-3, x.done.ray_cpu_seconds) << "rank " << x.rank;
          // Where the ray threads' time went: busy, waiting for tiles, waiting for blocks, each
          // part of the threads' run within the engine's frame, which began before the first tile.
          EXPECT_GE(x.done.tile_wait_seconds, 0.0) << "rank " << x.rank;
          EXPECT_GE(x.done.block_wait_seconds, 0.0) << "rank " << x.rank;
          EXPECT_GE(x.done.engine_seconds + 1e-3, x.done.seconds) << "rank " << x.rank;
          EXPECT_LE(x.done.busy_seconds + x.done.tile_wait_seconds + x.done.block_wait_seconds,
                    x.done.ray_threads * x.done.engine_seconds + 1e-3)
              << "rank " << x.rank;
        }
        EXPECT_EQ(x.done.ray_threads, 2u);
        busy += x.done.busy_seconds;
        offered += x.done.ray_threads * job.figures[f].seconds;
      }
      EXPECT_DOUBLE_EQ(job.figures[f].utilisation(), busy / offered);
      EXPECT_GT(job.figures[f].utilisation(), 0.0);
      if (rem && slaves > 1) {
        uint64_t fetches = 0, runs = 0;
        for (const master::SlaveFigures& x : job.figures[f].slaves) {
          fetches += x.done.fetches;
          runs += x.done.fetch_runs;
        }
        EXPECT_GE(runs, fetches);  // a request carries one run or more
        if (f == 0) {
          EXPECT_GT(fetches, 0u);
        }
      }
      // The master's record of who was given what (the preview's tiles in flight): each
      // slave's latest tiles (as many as it took, up to kPreviewTilesPerSlave), none twice.
      ASSERT_EQ(job.assigned[f].size(), static_cast<size_t>(slaves));
      std::set<std::tuple<int, int>> corners;
      size_t listed = 0;
      for (int i = 0; i < slaves; ++i) {
        const size_t took = job.figures[f].slaves[static_cast<size_t>(i)].done.tiles;
        const size_t kept = std::min(took, master::MasterNode::kPreviewTilesPerSlave);
        EXPECT_EQ(job.assigned[f][static_cast<size_t>(i)].size(), kept);
        listed += kept;
        for (const render::Tile& t : job.assigned[f][static_cast<size_t>(i)])
          EXPECT_TRUE(corners.insert({t.x0, t.y0}).second) << "tile handed out twice";
      }
      EXPECT_EQ(corners.size(), listed);
      EXPECT_LE(listed, tiles);
    }
  }
}

// Slaves in --mode bvh (one tree over every triangle, primary rays and their shadow rays as
// packets) under a master give the one-process image of the ray stack, bit for bit.
TEST(Distributed, SlavesInBvhModeGiveTheOneProcessImage) {
  TestStore s = BuildGenerated("spheres:30000");
  const render::Scene scene = TestScene(*s.reader, render::IntegratorType::kWhitted);
  const std::vector<image::ImageLayers> reference = ReferenceFrames(*s.reader, scene);
  const JobOutcome job = RunJob(*s.reader, scene, 2, false, 8, {}, nullptr, [] { return true; },
                                [](EngineOptions* o) {
                                  o->mode = TraceMode::kBvh;
                                  o->cache_bytes = 0;  // every block stays
                                });
  ASSERT_TRUE(job.master.ok()) << job.master.message();
  for (const Status& st : job.slaves) ASSERT_TRUE(st.ok()) << st.message();
  ASSERT_EQ(job.frames.size(), scene.cameras.size());
  for (size_t f = 0; f < scene.cameras.size(); ++f) {
    EXPECT_TRUE(SameBits(job.frames[f].rgba, reference[f].rgba)) << "frame " << f;
    EXPECT_TRUE(SameBits(job.frames[f].z, reference[f].z)) << "frame " << f;
    EXPECT_EQ(job.frames[f].samples, reference[f].samples) << "frame " << f;
  }
}

INSTANTIATE_TEST_SUITE_P(IntegratorsAndBlocks, DistributedImage,
                         ::testing::Combine(::testing::Values(render::IntegratorType::kWhitted,
                                                              render::IntegratorType::kPath),
                                            ::testing::Bool()));

// A slave that fails (a damaged block) or falls silent (killed) is dropped, its unfinished
// tiles' samples are taken back out of the film and others render them: the images equal the
// one-process images bit for bit. With --blocks rem, the silent slave owned blocks: the others
// read them from disk once the master says it is lost.
TEST(Distributed, ALostOrFailedSlaveCostsTimeNeverPixels) {
  TestStore s = BuildGenerated("spheres:30000");
  render::Scene scene = TestScene(*s.reader, render::IntegratorType::kPath);
  scene.default_material.type = render::MaterialType::kDiffuse;
  const std::vector<image::ImageLayers> reference = ReferenceFrames(*s.reader, scene);
  struct Case {
    const char* name;
    bool rem;
    JobFaults faults;
    const char* why;  // in the dropped slave's figures
  };
  JobFaults damaged, silent;
  damaged.damaged_rank = 2;
  silent.silent_rank = 3;
  silent.master.lost_after = std::chrono::milliseconds(2000);  // 4 heartbeats
  for (const Case& c : {Case{"damaged, loc", false, damaged, "damaged"},
                        Case{"silent, loc", false, silent, "no word from it"},
                        Case{"silent, rem", true, silent, "no word from it"}}) {
    const JobOutcome job = RunJob(*s.reader, scene, 3, c.rem, 8, c.faults);
    ASSERT_TRUE(job.master.ok()) << c.name << ": " << job.master.message();
    ASSERT_EQ(job.frames.size(), scene.cameras.size()) << c.name;
    const int dropped = c.faults.damaged_rank + c.faults.silent_rank;
    for (size_t f = 0; f < scene.cameras.size(); ++f) {
      EXPECT_TRUE(SameBits(job.frames[f].rgba, reference[f].rgba)) << c.name << ", frame " << f;
      EXPECT_EQ(job.frames[f].samples, reference[f].samples) << c.name << ", frame " << f;
      const master::SlaveFigures& lost = job.figures[f].slaves[static_cast<size_t>(dropped - 1)];
      EXPECT_TRUE(lost.dropped) << c.name;
      EXPECT_NE(lost.failure.find(c.why), std::string::npos) << c.name << ": " << lost.failure;
      // The live preview lists none of its tiles (the others took them) and says it is gone.
      EXPECT_TRUE(job.assigned[f][static_cast<size_t>(dropped - 1)].empty()) << c.name;
    }
    ASSERT_EQ(job.dropped.size(), 3u) << c.name;
    EXPECT_NE(job.dropped[static_cast<size_t>(dropped - 1)].find(c.why), std::string::npos)
        << c.name << ": " << job.dropped[static_cast<size_t>(dropped - 1)];
    for (int r = 1; r <= 3; ++r) {
      if (r != dropped) {
        EXPECT_EQ(job.dropped[static_cast<size_t>(r - 1)], "") << c.name;
      }
    }
    for (int r = 1; r <= 3; ++r)
      if (r != dropped) {
        EXPECT_TRUE(job.slaves[static_cast<size_t>(r - 1)].ok()) << c.name;
      }
  }
}

// Progressive passes through the master: the same bits as every sample at once in one
// process; and a stop rule that fires at once ends the job cleanly with what was merged.
TEST(DistributedProgressive, PassesGiveTheOneProcessImageAndAStopEndsCleanly) {
  TestStore s = BuildGenerated("spheres:30000");
  render::Scene scene = TestScene(*s.reader, render::IntegratorType::kPath);
  scene.default_material.type = render::MaterialType::kDiffuse;
  scene.integrator.spp = 5;
  scene.cameras.resize(1);
  const RenderOutcome one = Render(*s.reader, scene, Options(*s.reader));
  ASSERT_TRUE(one.status.ok()) << one.status.message();
  const render::Camera camera(scene.cameras[0]);
  for (render::PixelOrder order : {render::PixelOrder::kPriority, render::PixelOrder::kScanline}) {
    const render::FramePlan plan =
        render::MakeFramePlan(camera.width(), camera.height(), 8, 5, 0, order);
    const JobOutcome job = RunJob(*s.reader, scene, 2, false, 8, {}, &plan);
    ASSERT_TRUE(job.master.ok()) << job.master.message();
    ASSERT_EQ(job.frames.size(), 1u);
    EXPECT_TRUE(SameBits(job.frames[0].rgba, one.image.rgba)) << render::PixelOrderName(order);
    EXPECT_TRUE(SameBits(job.frames[0].variance, one.image.variance));
    EXPECT_EQ(job.frames[0].samples, one.image.samples);
  }
  const render::FramePlan plan =
      render::MakeFramePlan(camera.width(), camera.height(), 8, 5, 0, render::PixelOrder::kPriority);
  const JobOutcome stopped = RunJob(*s.reader, scene, 2, false, 8, {}, &plan, [] { return false; });
  ASSERT_TRUE(stopped.master.ok()) << stopped.master.message();
  for (const Status& st : stopped.slaves) EXPECT_TRUE(st.ok()) << st.message();
  ASSERT_EQ(stopped.frames.size(), 1u);
  uint64_t samples = 0;
  for (uint32_t n : stopped.frames[0].samples) samples += n;
  EXPECT_EQ(samples, 0u);  // asked before the first tile went out
}

TEST(FrameFigures, UtilisationIsTheSlavesBusyTimeOverTheThreadTimeOffered) {
  master::FrameFigures f;
  f.seconds = 2.0;
  f.slaves.resize(3);
  f.slaves[0].done.ray_threads = 1;
  f.slaves[0].done.busy_seconds = 1.5;
  f.slaves[1].done.ray_threads = 2;
  f.slaves[1].done.busy_seconds = 3.0;
  f.slaves[2].dropped = true;  // a lost slave's figures do not count
  f.slaves[2].done.ray_threads = 4;
  // (1.5 + 3.0) / ((1 + 2) x 2.0)
  EXPECT_DOUBLE_EQ(f.utilisation(), 0.75);
  f.slaves[0].done.busy_seconds = 0;
  EXPECT_DOUBLE_EQ(f.utilisation(), 0.5);
  master::FrameFigures none;
  EXPECT_EQ(none.utilisation(), 0.0);  // no frame: unknown, not a division by zero
}

TEST(TileScheduler, EveryTileOnceEachSlaveStartsInItsOwnRegion) {
  const std::vector<render::Tile> tiles = render::HilbertTiles(200, 120, 16);
  master::TileScheduler scheduler(tiles, 3);
  std::vector<std::vector<size_t>> got(3);
  size_t index;
  for (int round = 0; ; ++round) {
    bool any = false;
    for (int s = 0; s < 3; ++s) {
      if (s == 2 && round % 2) continue;  // slave 2 is slower: the others take over its span
      if (!scheduler.Next(s, &index)) continue;
      any = true;
      got[s].push_back(index);
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
  return node.RunFrame(0, render::HilbertTiles(16, 16, 8), 1, &film, [] {}, &figures);
}

// Rank 1's figures of frame 0, all zero but what `set` changes.
std::vector<uint8_t> FrameDoneWith(void (*set)(wire::FrameDone*)) {
  wire::FrameDone d{};
  set(&d);
  return wire::Encode(1, d);
}

TEST(Distributed, HostileMessagesEndTheFrameNamingTheSender) {
  std::vector<uint8_t> other_version = wire::Encode(1, wire::TileRequest{0, 0});
  other_version[4] = 99;  // never this build's
  for (const auto& [bytes, expected] :
       std::vector<std::pair<std::vector<uint8_t>, std::string>>{
           {other_version, "rank 1: protocol version 99"},
           {std::vector<uint8_t>(40, 0xab), "rank 1: not a raystack message"},
           {wire::Encode(2, wire::TileRequest{0, 0}), "claims to come from rank 2"},
           {wire::EncodeError(1, "block 9: checksum mismatch (the block is damaged)"),
            "rank 1: block 9: checksum mismatch"},
           {wire::Encode(1, wire::TileAssign{}), "only the master sends"},
           // Figures that would be written as "nan" into --stats (an unreadable JSON).
           {FrameDoneWith([](wire::FrameDone* d) { d->seconds = std::nan(""); }),
            "rank 1 reports frame 0 done with seconds nan"},
           {FrameDoneWith([](wire::FrameDone* d) { d->loader_busy_seconds = -1; }),
            "rank 1 reports frame 0 done with loader_busy_seconds -1"},
           {FrameDoneWith([](wire::FrameDone* d) { d->cache_hit_rate = 2; }),
            "rank 1 reports frame 0 done with cache_hit_rate 2"},
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

// Forwards to another transport, and notes which ranks it was told will not end with the job.
class EndNotingTransport : public transport::Transport {
 public:
  explicit EndNotingTransport(transport::Transport* inner) : inner_(inner) {}
  int rank() const override { return inner_->rank(); }
  int size() const override { return inner_->size(); }
  Status Send(int to, std::span<const uint8_t> bytes) override { return inner_->Send(to, bytes); }
  Expected<std::optional<transport::Envelope>> Receive(std::chrono::milliseconds timeout) override {
    return inner_->Receive(timeout);
  }
  void NoteRankWillNotEnd(int rank) override { died.push_back(rank); }
  std::vector<int> died;

 private:
  transport::Transport* inner_;
};

// A slave of another build (another protocol version) cannot read the master's shutdown
// either: the master does not wait for its acknowledgement (it waited 30 s, then hung in
// MPI_Finalize with the job), and marks it as gone so that this process ends without it.
TEST(Distributed, ASlaveOfAnotherProtocolIsNotWaitedForAtTheEnd) {
  transport::InProcessHub hub(3);
  auto master_end = hub.Endpoint(0);
  EndNotingTransport noting(master_end.get());
  auto deaf = hub.Endpoint(1);
  auto good = hub.Endpoint(2);
  std::vector<uint8_t> other_version = wire::Encode(1, wire::TileRequest{0, 0});
  other_version[4] = static_cast<uint8_t>(wire::kProtocolVersion - 1);
  ASSERT_TRUE(deaf->Send(0, other_version).ok());
  master::MasterNode node(&noting);
  render::Film film(16, 16);
  master::FrameFigures figures;
  const Status s = node.RunFrame(0, render::HilbertTiles(16, 16, 8), 1, &film, [] {}, &figures);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("rank 1: protocol version"), std::string::npos) << s.message();
  // Rank 2 acknowledges the end as a slave of this build does; rank 1 never can.
  std::thread acknowledge([&] {
    for (;;) {
      Expected<std::optional<transport::Envelope>> got = good->Receive(std::chrono::milliseconds(50));
      ASSERT_TRUE(got.ok());
      if (!got->has_value()) continue;
      const Expected<wire::Message> m = wire::Decode((*got)->bytes, 0);
      if (m.ok() && m->type() == wire::MessageType::kShutdown) break;
    }
    ASSERT_TRUE(good->Send(0, wire::Encode(2, wire::Shutdown{0, 0})).ok());
  });
  // Without the fix this waits the whole hour for rank 1 (ctest's timeout ends it).
  EXPECT_FALSE(node.Shutdown(1, std::chrono::hours(1)));
  acknowledge.join();
  EXPECT_EQ(noting.died, std::vector<int>{1});
}

// A master killed, or a slave's host cut off from it: the slaves waited for tiles or for the
// shutdown forever (under mpirun --enable-recovery the job never ended). The master beats
// (MasterOptions::beat); a slave that has not heard it for master_lost_after takes it for gone
// and ends, saying why.
TEST(Distributed, ASlaveWhoseMasterFallsSilentEndsInsteadOfWaiting) {
  transport::InProcessHub hub(2);
  auto master_end = hub.Endpoint(0);
  auto slave_end = hub.Endpoint(1);
  ASSERT_TRUE(master_end->Send(1, wire::Encode(0, wire::Heartbeat{0, 0})).ok());  // then silence
  slave::SlaveNode node(slave_end.get(), nullptr, nullptr, {}, std::chrono::milliseconds(300));
  // Without the check this waits the whole hour (ctest's timeout ends it).
  const Expected<uint32_t> r = node.WaitForShutdown(std::chrono::hours(1));
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("the master (rank 0) has said nothing"), std::string::npos)
      << r.status().message();
  EXPECT_TRUE(node.master_lost());
}

// The master's beat: a heartbeat to every slave from the start, until the shutdown.
TEST(Distributed, TheMasterBeatsUntilTheShutdown) {
  transport::InProcessHub hub(3);
  auto master_end = hub.Endpoint(0);
  std::vector<std::unique_ptr<transport::Transport>> slaves;
  for (int r = 1; r <= 2; ++r) slaves.push_back(hub.Endpoint(r));
  master::MasterOptions options;
  options.beat = true;
  master::MasterNode node(master_end.get(), options);
  for (auto& slave : slaves) {
    Expected<std::optional<transport::Envelope>> got = slave->Receive(std::chrono::hours(1));
    ASSERT_TRUE(got.ok() && got->has_value());
    const Expected<wire::Message> m = wire::Decode((*got)->bytes, 0);
    ASSERT_TRUE(m.ok());
    EXPECT_EQ(m->type(), wire::MessageType::kHeartbeat);
    ASSERT_TRUE(slave->Send(0, wire::Encode(static_cast<uint32_t>(slave->rank()), wire::Shutdown{0, 0})).ok());
  }
  EXPECT_TRUE(node.Shutdown(0, std::chrono::hours(1)));
  // After the shutdown message, nothing more from the master.
  for (auto& slave : slaves) {
    bool shutdown = false;
    for (;;) {
      Expected<std::optional<transport::Envelope>> got = slave->Receive(std::chrono::milliseconds(0));
      ASSERT_TRUE(got.ok());
      if (!got->has_value()) break;
      const Expected<wire::Message> m = wire::Decode((*got)->bytes, 0);
      ASSERT_TRUE(m.ok());
      if (m->type() == wire::MessageType::kShutdown) shutdown = true;
      else EXPECT_FALSE(shutdown) << "a " << wire::MessageTypeName(m->type()) << " after the shutdown";
    }
    EXPECT_TRUE(shutdown);
  }
}

// Rank 1 of `hub` as a real slave rendering frame 0 of `scene` while the test plays the
// master, then waiting for the end of the job; `frame_ok`: whether its frame should succeed.
std::thread SlaveAlone(transport::InProcessHub* hub, const store::StoreReader& store,
                       const render::Scene& scene, const EngineOptions& options, bool frame_ok) {
  return std::thread([hub, &store, &scene, options, frame_ok] {
    auto net = hub->Endpoint(1);
    auto engine = slave::RenderEngine::Create(store, options);
    ASSERT_TRUE(engine.ok());
    const render::MaterialTable materials = render::MaterialTable::Build(store.materials(), scene);
    slave::SlaveNode node(net.get(), engine->get());
    slave::RenderStats stats;
    EXPECT_EQ(node.RunFrame(0, scene, materials, render::Camera(scene.cameras[0]), &stats).ok(),
              frame_ok);
    (void)node.WaitForShutdown(std::chrono::seconds(60));
  });
}

// A slave thread keeps two tiles asked for ahead of the one it renders (with --tile-ahead 0,
// from the moment it starts it): a small tile takes about as long as the master's answer.
// The test plays the master: it answers the first request only, and counts the requests.
TEST(Distributed, ASlaveThreadAsksForTwoTilesAheadOfItsCurrentOne) {
  TestStore s = BuildGenerated("spheres:20000");
  render::Scene scene = TestScene(*s.reader, render::IntegratorType::kWhitted);
  transport::InProcessHub hub(2);
  EngineOptions o = Options(*s.reader);
  o.threads = 1;
  std::thread slave_thread = SlaveAlone(&hub, *s.reader, scene, o, true);
  auto master = hub.Endpoint(0);
  int requests = 0;
  bool frame_done = false;
  auto assign = [&](bool none) {
    wire::TileAssign a{};
    a.frame = 0;
    a.thread = 0;
    if (none) {
      a.none = 1;
    } else {
      a.x0 = 0, a.y0 = 0, a.x1 = 8, a.y1 = 8;
    }
    ASSERT_TRUE(master->Send(1, wire::Encode(0, a)).ok());
  };
  // Until three requests came (the first, answered with a tile, and two ahead of it) or 5 s
  // passed without a request (heartbeats come meanwhile).
  auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (requests < 3 && std::chrono::steady_clock::now() < deadline) {
    auto e = master->Receive(std::chrono::milliseconds(100));
    ASSERT_TRUE(e.ok());
    if (!e->has_value()) continue;
    const Expected<wire::Message> m = wire::Decode((*e)->bytes, 1);
    ASSERT_TRUE(m.ok()) << m.status().message();
    if (m->type() != wire::MessageType::kTileRequest) continue;  // pixels, heartbeats
    if (++requests == 1) assign(false);
    deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  }
  EXPECT_EQ(requests, 3);
  for (int i = 1; i < requests; ++i) assign(true);  // no more tiles: the frame ends
  while (!frame_done) {
    auto e = master->Receive(std::chrono::seconds(30));
    ASSERT_TRUE(e.ok() && e->has_value());
    const Expected<wire::Message> m = wire::Decode((*e)->bytes, 1);
    ASSERT_TRUE(m.ok());
    frame_done = m->type() == wire::MessageType::kFrameDone;
    EXPECT_NE(m->type(), wire::MessageType::kTileRequest) << "a request after the frame's end";
  }
  ASSERT_TRUE(master->Send(1, wire::Encode(0, wire::Shutdown{0, 0})).ok());
  slave_thread.join();
}

// A slave whose frame fails (a damaged block) while one of its threads waits for a tile the
// master holds back (the master gives a request nothing until every tile out is finished, and
// this slave's never will be) tells the master, rather than wait for that answer forever. The
// test plays the master: thread 0 gets one pixel and then nothing; thread 1 gets the frame,
// whose 8th block read is damaged.
TEST(Distributed, AFailingSlaveDoesNotWaitForATileHeldBack) {
  TestStore s = BuildGenerated("spheres:20000");
  render::Scene scene = TestScene(*s.reader, render::IntegratorType::kWhitted);
  transport::InProcessHub hub(2);
  EngineOptions o = Options(*s.reader);
  o.faults.corrupt_read = 8;
  std::thread slave_thread = SlaveAlone(&hub, *s.reader, scene, o, false);
  auto master = hub.Endpoint(0);
  const render::Camera camera(scene.cameras[0]);
  auto assign = [&](uint32_t thread, int x1, int y1) {
    wire::TileAssign a{};
    a.thread = thread;
    a.x0 = 0, a.y0 = 0, a.x1 = x1, a.y1 = y1;
    ASSERT_TRUE(master->Send(1, wire::Encode(0, a)).ok());
  };
  bool thread0_done = false, thread1_given = false, error = false;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (!error && std::chrono::steady_clock::now() < deadline) {
    auto e = master->Receive(std::chrono::milliseconds(100));
    ASSERT_TRUE(e.ok());
    if (!e->has_value()) continue;
    const Expected<wire::Message> m = wire::Decode((*e)->bytes, 1);
    ASSERT_TRUE(m.ok()) << m.status().message();
    if (m->type() == wire::MessageType::kTileRequest && m->tile_request().thread == 0 &&
        !thread0_done && m->tile_request().frame == 0) {
      assign(0, 1, 1);  // its first request; the next ones are held back
      thread0_done = true;
    } else if (m->type() == wire::MessageType::kPixelBatch && thread0_done && !thread1_given) {
      assign(1, camera.width(), camera.height());  // thread 0's pixel is in: it waits now
      thread1_given = true;
    }
    error = m->type() == wire::MessageType::kError;
  }
  EXPECT_TRUE(thread1_given);
  EXPECT_TRUE(error) << "the slave did not report its failure";
  ASSERT_TRUE(master->Send(1, wire::Encode(0, wire::Shutdown{0, 0})).ok());
  slave_thread.join();
}

// A master's tile outside the image (a hostile or broken master) is refused by the slave,
// which reports it, rather than render 2^31 x 2^31 pixels or write over other pixels.
TEST(Distributed, ASlaveRefusesATileOutsideTheImage) {
  TestStore s = BuildGenerated("spheres:20000");
  render::Scene scene = TestScene(*s.reader, render::IntegratorType::kWhitted);
  const render::Camera camera(scene.cameras[0]);
  for (const auto& [x1, y1] : std::vector<std::pair<int32_t, int32_t>>{
           {camera.width() + 1, 8}, {8, std::numeric_limits<int32_t>::max()}}) {
    transport::InProcessHub hub(2);
    EngineOptions o = Options(*s.reader);
    o.threads = 1;
    std::thread slave_thread = SlaveAlone(&hub, *s.reader, scene, o, false);
    auto master = hub.Endpoint(0);
    std::string error;
    bool assigned = false;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (error.empty() && std::chrono::steady_clock::now() < deadline) {
      auto e = master->Receive(std::chrono::milliseconds(100));
      ASSERT_TRUE(e.ok());
      if (!e->has_value()) continue;
      const Expected<wire::Message> m = wire::Decode((*e)->bytes, 1);
      ASSERT_TRUE(m.ok()) << m.status().message();
      if (m->type() == wire::MessageType::kTileRequest && !assigned) {
        wire::TileAssign a{};
        a.x0 = 0, a.y0 = 0, a.x1 = x1, a.y1 = y1;
        ASSERT_TRUE(master->Send(1, wire::Encode(0, a)).ok());
        assigned = true;
      }
      if (m->type() == wire::MessageType::kError) error = m->error_text();
    }
    EXPECT_NE(error.find("outside the " + std::to_string(camera.width()) + "x" +
                         std::to_string(camera.height()) + " image"),
              std::string::npos)
        << error;
    ASSERT_TRUE(master->Send(1, wire::Encode(0, wire::Shutdown{0, 0})).ok());
    slave_thread.join();
  }
}

TEST(Distributed, WhenEverySlaveFailsTheJobEndsWithTheirErrors) {
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
                                      1, &film, [] {}, &figures);
  EXPECT_TRUE(node.Shutdown(1));  // every slave acknowledges, the failed one too
  for (std::thread& t : threads) t.join();
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.message().find("no slave is left"), std::string::npos) << status.message();
  EXPECT_NE(status.message().find("damaged"), std::string::npos) << status.message();
  EXPECT_NE(status.message().find("rank 1: "), std::string::npos) << status.message();
  EXPECT_NE(status.message().find("rank 2: "), std::string::npos) << status.message();
}

}  // namespace
}  // namespace raystack::testing
