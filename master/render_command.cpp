#include "master/render_command.h"

#include <atomic>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <mutex>
#include <string>
#include <thread>

#include "common/base/log.h"
#include "common/base/progress.h"
#include "common/image/exr_io.h"
#include "common/image/png_writer.h"
#include "common/render/camera.h"
#include "common/render/film.h"
#include "common/render/material_table.h"
#include "common/render/scene.h"
#include "common/store/store_reader.h"
#include "common/mpi/mpi_transport.h"
#include "master/checkpoints.h"
#include "master/convergence_monitor.h"
#include "master/frame_writer.h"
#include "master/master_node.h"
#include "master/preflight.h"
#include "master/preview/live_preview.h"
#include "master/provenance.h"
#include "master/resume.h"
#include "slave/direct_reads.h"
#include "slave/peer_blocks.h"
#include "slave/render_engine.h"
#include "slave/slave_node.h"

namespace raystack::master {
namespace {

// --cache-mb counts MiB (2^20 bytes), and the messages about the cache say MiB too.
constexpr double kMiB = 1024.0 * 1024.0;

constexpr const char* kUsage = R"(usage: raystack render SCENE.json [options]

Renders a block store (made by raystack-prep) as the scene file describes (format:
common/render/SCENE_FORMAT.md) and writes an OpenEXR image with layers R G B A, Z, N, albedo,
samples and variance, plus a tone-mapped PNG beside it. Blocks are loaded on demand into a
cache of --cache-mb; rays that need a missing block wait in that block's queue while a
loader thread reads it (the ray stack), so the store may be far larger than the cache.

options:
  --mode stack|sync|incore|bvh
                            stack: the ray stack (default); sync: a miss blocks the thread
                            while its block is read (the baseline); incore: load every block
                            first, no budget; bvh: load every block, then trace through one
                            BVH over all triangles (the fastest when the model fits in RAM;
                            needs about twice incore's memory; same image)
  --cache-mb N              block cache budget in MiB, never exceeded (default 512)
  --threads N               ray threads (default: all cores)
  --feed-fraction P         start the next tile once this fraction of the current one is
                            done (default 0.1)
  --tile-size N             tile side in pixels (default 32)
  --tile-ahead P            under mpirun, a slave thread asks for its next two tiles once
                            this fraction of its current one is done (default 0: at once)
  --batch N                 samples per pixel batch a slave sends (default 1024)
  --checkpoint-s S          write the EXR every S seconds while rendering (default 0: only
                            at the end), on a thread of its own at low priority while the
                            render goes on, atomically (a temporary file, then a rename); a
                            failed checkpoint is logged and tried again, never fatal
  --resume                  continue from the output EXR a killed run left (its last
                            checkpoint): tiles it holds finished are kept, the others are
                            rendered again; the image equals an uninterrupted run's
  --io-threads N            block reads kept in flight by the loader (default 32)
  --blocks loc|rem|auto     under mpirun, where a slave gets a missing block: loc, the store
                            itself (local disk or shared filesystem); rem, the memory of the
                            block's owner among the slaves (each block is read from disk once,
                            by its owner, whose share counts against its --cache-mb); auto
                            (default): rem when a slave's share fits half its budget, else loc
  --direct-io auto|on|off   read blocks past the kernel's page cache (O_DIRECT): on, off,
                            or auto (default): on when the store's blocks.bin does not fit
                            the memory available (or a cgroup limit) next to --cache-mb,
                            where the page cache would only copy and reclaim each block
  --io-latency-us N         add N microseconds to every block read (emulates a network
                            filesystem; for measurements)
  --spp N                   samples per pixel (overrides the scene's integrator.spp)
  --pass-spp N              samples per pixel per progressive pass (default 0: passes of
                            1, 1, 2, 4, ... samples, every pixel having 2^k before any has
                            more); the image is the same whatever the passes
  --pixel-order priority|scanline
                            priority (default): tiles along a Hilbert curve, the first pass
                            in rounds of the priority matrix (1/256 of the pixels spread
                            over the frame, then 3/256, ...), pixels by priority; scanline:
                            tiles and pixels left to right, top to bottom (for comparison)
  --coarse-rounds auto|on|off
                            in priority order, render the first pass in the priority
                            matrix's rounds (a coarse full frame early) or in one sweep;
                            auto (default): rounds when the store's decoded blocks fit in
                            --cache-mb, one sweep otherwise (out of core every round would
                            load the frame's blocks again)
  --time-limit S            stop handing out work after S seconds (per frame); the image
                            keeps every sample merged, with its per-pixel counts (the EXR's
                            samples layer)
  --target-error E          stop after the first pass whose estimated error (RMSE of
                            luminance from the per-pixel variance, see --convergence-log)
                            is <= E, once every pixel has 2 samples
  --convergence-log FILE    write a CSV row every --log-interval seconds and at every pass
                            end: time, rays, samples, pixels covered, the fewest samples
                            of a pixel, the error estimates, and RMSE and relMSE against
                            --reference (format: README, "Error against run time")
  --log-interval S          seconds between convergence-log rows (default 0.5)
  --reference REF.exr       an image to measure RMSE and relMSE against (same size; with
                            several cameras REF-0.exr, REF-1.exr, ...)
  --output FILE.exr         override the scene's output path (the PNG goes beside it;
                            several cameras: FILE-0.exr, FILE-1.exr, ...)
  --no-png                  do not write the PNG quick-look
  --exposure EV             exposure of the PNG quick-look (default 0)
  --stats FILE              also write the run's statistics as JSON
  --preview PORT|any        serve a live preview of the render at http://ADDR:PORT/ (any: a
                            free port; the address is printed at start); default off
  --preview-bind ADDR       the preview's address (default 127.0.0.1, this machine only; any
                            other, e.g. 0.0.0.0, requires the random token printed at start)
  --preview-hold S          keep the preview up S seconds after the render (Ctrl-C ends it)
  --lost-after S            under mpirun, the master drops a slave it has not heard from for
                            S seconds (default 5; slaves send a heartbeat every 0.5 s); its
                            unfinished tiles go to the others, and the image stays exact.
                            Start the job with `mpirun --enable-recovery` so that a dead
                            slave does not end every rank
  -q, --quiet               no progress or information lines (warnings and errors
                            are still printed)
  -h, --help                this text

fault injection (for tests and drills):
  --fault-rank R            apply the faults below on rank R only (default: every slave)
  --fault-kill-after-tiles N  the slave kills itself (SIGKILL, as kill -9) when given its
                            N-th tile
  --fault-stall-after-tiles N  the slave's whole process stops (SIGSTOP) when given its N-th
                            tile, and goes on after --fault-stall-s S (default 5): a stalled
                            node, alive but silent
  --fault-fail-read K       the slave's K-th block read (0-based) fails, as a disk error
  --fault-kill-after-checkpoints N  the one process, or the master, kills itself (SIGKILL)
                            right after its N-th checkpoint: the whole job dies (--resume)
  --fault-fail-checkpoints N  the first N checkpoint writes fail, as on a full disk
)";

struct Args {
  std::string scene;
  slave::EngineOptions engine;
  int tile_size = 32;
  std::string output;
  bool png = true;
  float exposure = 0;
  std::string stats;
  bool quiet = false;
  double checkpoint_s = 0;
  std::string blocks = "auto";
  std::string coarse_rounds = "auto";  // --coarse-rounds
  slave::DirectIo direct_io = slave::DirectIo::kAuto;
  uint32_t spp = 0;       // 0: the scene's
  uint32_t pass_spp = 0;  // 0: doubling passes
  StopRules stop;
  std::string convergence_log;
  double log_interval_s = 0.5;
  std::string reference;
  double lost_after_s = 5;
  bool resume = false;
  int fault_rank = 0;  // 0: every slave
  int64_t kill_after_tiles = -1;
  int64_t stall_after_tiles = -1;
  double stall_s = 5;
  int64_t fail_read = -1;
  int64_t kill_after_checkpoints = -1;
  int64_t fail_checkpoints = 0;
  preview::LivePreviewOptions preview;
};

template <typename T>
bool ParseNumber(const std::string& s, T* out) {
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), *out);
  return ec == std::errc() && p == s.data() + s.size();
}

Status ParseArgs(int argc, char** argv, Args* a, bool* help) {
  a->engine.threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&](std::string* out) -> Status {
      if (i + 1 >= argc) return Status::Error(arg + " needs a value");
      *out = argv[++i];
      return OkStatus();
    };
    auto number = [&](auto* out, double lo, double hi) -> Status {
      std::string v;
      RAYSTACK_RETURN_IF_ERROR(value(&v));
      // Written so that NaN ("nan" parses) is out of every range.
      if (!ParseNumber(v, out) || !(static_cast<double>(*out) >= lo && static_cast<double>(*out) <= hi))
        return Status::Error(StrFormat("%s: '%s' is not a number from %g to %g", arg.c_str(),
                                       v.c_str(), lo, hi));
      return OkStatus();
    };
    if (arg == "-h" || arg == "--help") {
      *help = true;
      return OkStatus();
    } else if (arg == "--mode") {
      std::string v;
      RAYSTACK_RETURN_IF_ERROR(value(&v));
      Expected<slave::TraceMode> mode = slave::ParseTraceMode(v);
      if (!mode.ok()) return mode.status();
      a->engine.mode = *mode;
    } else if (arg == "--cache-mb") {
      double mb;
      RAYSTACK_RETURN_IF_ERROR(number(&mb, 0.001, 1 << 24));
      a->engine.cache_bytes = static_cast<uint64_t>(mb * 1024 * 1024);
    } else if (arg == "--threads") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->engine.threads, 1, slave::BlockLoader::kMaxRayThreads));
    } else if (arg == "--feed-fraction") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->engine.feed_fraction, 0, 1));
    } else if (arg == "--tile-size") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->tile_size, 1, 4096));
    } else if (arg == "--blocks") {
      RAYSTACK_RETURN_IF_ERROR(value(&a->blocks));
      if (a->blocks != "loc" && a->blocks != "rem" && a->blocks != "auto")
        return Status::Error("--blocks must be loc, rem or auto, got '" + a->blocks + "'");
    } else if (arg == "--tile-ahead") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->engine.tile_ahead, 0, 1));
    } else if (arg == "--batch") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->engine.result_batch, 1, 65536));
    } else if (arg == "--checkpoint-s") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->checkpoint_s, 0, 1e9));
    } else if (arg == "--io-threads") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->engine.loader.io_threads, 1, 256));
    } else if (arg == "--direct-io") {
      std::string v;
      RAYSTACK_RETURN_IF_ERROR(value(&v));
      Expected<slave::DirectIo> mode = slave::ParseDirectIo(v);
      if (!mode.ok()) return mode.status();
      a->direct_io = *mode;
    } else if (arg == "--io-latency-us") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->engine.faults.io_latency_us, 0, 10'000'000));
    } else if (arg == "--spp") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->spp, 1, 65535));  // as the scene file allows
    } else if (arg == "--pass-spp") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->pass_spp, 0, 65535));
    } else if (arg == "--pixel-order") {
      std::string v;
      RAYSTACK_RETURN_IF_ERROR(value(&v));
      Expected<render::PixelOrder> order = render::ParsePixelOrder(v);
      if (!order.ok()) return order.status();
      a->engine.pixel_order = *order;
    } else if (arg == "--coarse-rounds") {
      RAYSTACK_RETURN_IF_ERROR(value(&a->coarse_rounds));
      if (a->coarse_rounds != "auto" && a->coarse_rounds != "on" && a->coarse_rounds != "off")
        return Status::Error("--coarse-rounds must be auto, on or off, not '" + a->coarse_rounds + "'");
    } else if (arg == "--time-limit") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->stop.time_limit_s, 1e-3, 1e9));
    } else if (arg == "--target-error") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->stop.target_error, 1e-12, 1e30));
    } else if (arg == "--convergence-log") {
      RAYSTACK_RETURN_IF_ERROR(value(&a->convergence_log));
    } else if (arg == "--log-interval") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->log_interval_s, 0.01, 1e6));
    } else if (arg == "--reference") {
      RAYSTACK_RETURN_IF_ERROR(value(&a->reference));
    } else if (arg == "--output") {
      RAYSTACK_RETURN_IF_ERROR(value(&a->output));
      if (a->output.empty()) return Status::Error("--output needs a path (an .exr file)");
    } else if (arg == "--no-png") {
      a->png = false;
    } else if (arg == "--exposure") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->exposure, -64, 64));
    } else if (arg == "--preview") {
      std::string v;
      RAYSTACK_RETURN_IF_ERROR(value(&v));
      uint16_t port = 0;
      if (v != "any" && (!ParseNumber(v, &port)))
        return Status::Error("--preview: '" + v + "' is not a port number (0 to 65535) or 'any'");
      a->preview.enabled = v == "any" || port != 0;
      a->preview.server.port = port;
    } else if (arg == "--preview-bind") {
      RAYSTACK_RETURN_IF_ERROR(value(&a->preview.server.bind));
    } else if (arg == "--preview-hold") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->preview.hold_seconds, 0, 1e9));
    } else if (arg == "--stats") {
      RAYSTACK_RETURN_IF_ERROR(value(&a->stats));
    } else if (arg == "--resume") {
      a->resume = true;
    } else if (arg == "--lost-after") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->lost_after_s, 0.5, 1e6));
    } else if (arg == "--fault-rank") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->fault_rank, 1, 1 << 20));
    } else if (arg == "--fault-kill-after-tiles") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->kill_after_tiles, 1, 1e12));
    } else if (arg == "--fault-stall-after-tiles") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->stall_after_tiles, 1, 1e12));
    } else if (arg == "--fault-stall-s") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->stall_s, 0.0, 3600.0));
    } else if (arg == "--fault-kill-after-checkpoints") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->kill_after_checkpoints, 1, 1e12));
    } else if (arg == "--fault-fail-checkpoints") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->fail_checkpoints, 0, 1e12));
    } else if (arg == "--fault-fail-read") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->fail_read, 0, 1e12));
    } else if (arg == "-q" || arg == "--quiet") {
      a->quiet = true;
    } else if (!arg.empty() && arg[0] == '-') {
      return Status::Error("unknown option " + arg + " (see --help)");
    } else if (a->scene.empty()) {
      a->scene = arg;
    } else {
      return Status::Error("one scene file only; extra argument '" + arg + "'");
    }
  }
  if (!*help && a->scene.empty()) return Status::Error("a scene file is required (see --help)");
  a->preview.server.exposure = a->exposure;
  return OkStatus();
}

Status WriteStats(const std::string& path, const std::string& json) {
  if (path.empty()) return OkStatus();
  std::ofstream out(path);
  out << json;
  if (!out) return Status::Error(path + ": cannot write the statistics");
  return OkStatus();
}

std::string OutputOf(const Args& args, const render::Scene& scene) {
  return args.output.empty() ? scene.output : args.output;
}

// Queues frame `f`'s EXR (and the PNG quick look) of the resolved film `layers` to `writer`;
// returns the EXR's path, or the error of an earlier frame's write.
Expected<std::string> WriteFrame(const Args& args, const render::Scene& scene, size_t f,
                                 const render::Film& film, image::ImageLayers layers,
                                 FrameWriter* writer) {
  const size_t frames = scene.cameras.size();
  const std::string output = OutputOf(args, scene);
  FrameWriter::Image image;
  image.exr = FramePath(output, f, frames, ".exr");
  if (args.png) image.png = FramePath(output, f, frames, ".png");
  image.exposure = args.exposure;
  image.background = f + 1 < frames;  // the next frame renders while it is written
  image.layers = std::move(layers);
  image.layers.provenance = Provenance(scene, f);
  if (film.nonfinite_dropped() > 0)
    LOG_WARNING("render", "%llu samples with NaN or Inf radiance were dropped",
                static_cast<unsigned long long>(film.nonfinite_dropped()));
  const std::string exr = image.exr;
  RAYSTACK_RETURN_IF_ERROR(writer->Write(std::move(image)));
  return exr;
}

// The film for the next frame: the previous frame's, cleared, when the size is the same
// (Film::Clear: a few milliseconds instead of ~20 of page faults between two frames).
render::Film& FilmFor(const render::Camera& camera, std::unique_ptr<render::Film>* film) {
  if (*film && (*film)->width() == camera.width() && (*film)->height() == camera.height())
    (*film)->Clear();
  else
    *film = std::make_unique<render::Film>(camera.width(), camera.height());
  return **film;
}

// The scene file, with the command line's overrides.
Expected<render::Scene> LoadSceneFor(const Args& args) {
  Expected<render::Scene> scene = render::LoadScene(args.scene);
  if (scene.ok() && args.spp > 0) scene->integrator.spp = static_cast<int>(args.spp);
  return scene;
}

render::FramePlan PlanOf(const Args& args, const render::Scene& scene, const render::Camera& camera,
                         bool coarse_rounds) {
  return render::MakeFramePlan(camera.width(), camera.height(), args.tile_size,
                               static_cast<uint32_t>(scene.integrator.spp), args.pass_spp,
                               args.engine.pixel_order, coarse_rounds);
}

// --coarse-rounds auto: the first pass's rounds sweep the frame five times, which costs nothing
// when the blocks stay in the cache and reloads them on every sweep when they do not (the
// dragon x36 with a 72 MB cache: 4.5 loads per block used instead of 1.1). `store` may be null
// (a master that cannot open it): then the rounds stay on, as for an in-core scene.
bool CoarseRounds(const Args& args, const store::StoreReader* store, std::string* why) {
  if (args.coarse_rounds != "auto") {
    *why = "--coarse-rounds " + args.coarse_rounds;
    return args.coarse_rounds == "on";
  }
  if (!store) {
    *why = "the store's size is unknown here";
    return true;
  }
  const uint64_t decoded = store->summary().raw_bytes;
  const bool fits = decoded <= args.engine.cache_bytes;
  *why = StrFormat("decoded blocks %.1f MB %s the %.1f MiB cache", static_cast<double>(decoded) / 1e6,
                   fits ? "fit in" : "exceed", static_cast<double>(args.engine.cache_bytes) / kMiB);
  return fits;
}

void LogFirstPass(const Args& args, bool rounds, const std::string& why) {
  if (args.quiet || args.engine.pixel_order != render::PixelOrder::kPriority) return;
  std::printf("first pass: %s (%s)\n", rounds ? "5 coarse rounds" : "one sweep", why.c_str());
}

// What a frame is measured against, if anything: --reference (REF-f.exr with several cameras).
// Frame f's reference into `*ref` (null without --reference), read into the memory of the frame
// before's: new memory for a 960x540 reference was ~50 ms of page faults at every frame's start.
Status LoadReference(const Args& args, size_t f, size_t frames, const render::Camera& camera,
                     std::unique_ptr<image::ImageLayers>* ref) {
  if (args.reference.empty()) {
    ref->reset();
    return OkStatus();
  }
  const std::string path = frames > 1 ? FramePath(args.reference, f, frames, ".exr") : args.reference;
  if (!*ref) *ref = std::make_unique<image::ImageLayers>();
  Status s = image::ReadExrInto(path, ref->get());
  if (s.ok()) s = render::CheckReference(**ref, camera.width(), camera.height(), path);
  if (!s.ok()) ref->reset();
  return s;
}

Expected<std::unique_ptr<ConvergenceLog>> OpenLog(const Args& args) {
  if (args.convergence_log.empty()) return std::unique_ptr<ConvergenceLog>();
  return ConvergenceLog::Open(args.convergence_log);
}

void ReportStop(const Args& args, const ConvergenceMonitor& monitor) {
  if (monitor.stopped() && !args.quiet) std::printf("stopped: %s\n", monitor.stop_reason().c_str());
}

// --resume: the pixels frame `f`'s checkpoint holds finished go into `film`, and the plan keeps
// only the tiles that still have a pixel to render.
Status ResumeInto(const Args& args, const render::Scene& scene, size_t f,
                  render::FramePlan* plan, render::Film* film) {
  if (!args.resume) return OkStatus();
  const std::string exr = FramePath(OutputOf(args, scene), f, scene.cameras.size(), ".exr");
  Expected<ResumePlan> resume =
      PlanResume(exr, plan->width, plan->height, plan->spp(), Provenance(scene, f));
  if (!resume.ok()) return resume.status();
  size_t tiles = 0;
  for (render::Sweep& sweep : plan->sweeps) {
    std::erase_if(sweep.tiles, [&](const render::Tile& t) { return !resume->Needs(t); });
    tiles += sweep.tiles.size();
  }
  ApplyResume(*resume, film);
  if (!args.quiet && resume->finished.empty())
    std::printf("resume frame %zu: no checkpoint at %s, every tile to render\n", f, exr.c_str());
  else if (!args.quiet)
    std::printf("resume frame %zu: %zu of %llu pixels finished in %s, %zu tiles to render\n", f,
                resume->kept_pixels.size(),
                static_cast<unsigned long long>(plan->width) * static_cast<unsigned long long>(plan->height),
                exr.c_str(), tiles);
  return OkStatus();
}

// The frame plan's tiles, as PlanTileSource, remembering which were handed out (the live
// preview shows the ones still in flight).
class WatchedTileSource final : public slave::TileSource {
 public:
  explicit WatchedTileSource(const render::FramePlan& plan) : tiles_(plan) {}
  bool Next(uint32_t thread, slave::Tile* tile) override {
    if (!tiles_.Next(thread, tile)) return false;
    std::lock_guard lock(mu_);
    given_.push_back(*tile);
    return true;
  }
  std::vector<preview::RankTiles> Given() const {
    std::lock_guard lock(mu_);
    return {preview::RankTiles{0, given_}};
  }
  void Stop() { tiles_.Stop(); }  // a stop rule holds

 private:
  slave::PlanTileSource tiles_;
  mutable std::mutex mu_;
  std::vector<render::Tile> given_;
};

Status Run(const Args& args) {
  Expected<render::Scene> scene = LoadSceneFor(args);
  if (!scene.ok()) return scene.status();
  const std::string output = OutputOf(args, *scene);
  const size_t frames = scene->cameras.size();
  RAYSTACK_RETURN_IF_ERROR(CheckMemory(*scene, 0));  // the film alone, before the store is read
  RAYSTACK_RETURN_IF_ERROR(CheckOutputs(*scene, output, args.png, args.checkpoint_s > 0));
  RAYSTACK_RETURN_IF_ERROR(CheckReferences(*scene, args.reference));
  Expected<std::unique_ptr<ConvergenceLog>> log = OpenLog(args);
  if (!log.ok()) return log.status();

  Expected<std::unique_ptr<store::StoreReader>> store = store::StoreReader::Open(scene->store);
  if (!store.ok()) return store.status();
  // With the blocks this process will hold: all of them in core, else at most its cache.
  const uint64_t decoded = (*store)->summary().raw_bytes;
  const bool all_blocks =
      args.engine.mode == slave::TraceMode::kIncore || args.engine.mode == slave::TraceMode::kBvh;
  RAYSTACK_RETURN_IF_ERROR(
      CheckMemory(*scene, all_blocks ? decoded : std::min(decoded, args.engine.cache_bytes)));
  std::string reads;
  RAYSTACK_RETURN_IF_ERROR(
      slave::ChooseReads(args.direct_io, args.engine.cache_bytes, store->get(), &reads));
  if (!args.quiet) std::printf("reads: %s\n", reads.c_str());
  Expected<std::unique_ptr<slave::RenderEngine>> engine =
      slave::RenderEngine::Create(**store, args.engine);
  if (!engine.ok()) return engine.status();
  const render::MaterialTable materials =
      render::MaterialTable::Build((*store)->materials(), *scene);
  Expected<preview::LivePreview> preview = preview::LivePreview::Start(args.preview);
  if (!preview.ok()) return preview.status();

  std::string why;
  const bool coarse_rounds = CoarseRounds(args, store->get(), &why);
  LogFirstPass(args, coarse_rounds, why);
  std::string stats_json = "[\n";
  FrameWriter writer(!args.quiet);
  std::unique_ptr<render::Film> reused_film;  // FilmFor
  std::unique_ptr<image::ImageLayers> reference;  // LoadReference
  for (size_t f = 0; f < frames; ++f) {
    const render::Camera camera(scene->cameras[f]);
    render::Film& film = FilmFor(camera, &reused_film);
    render::FilmSink sink(&film);
    render::FramePlan plan = PlanOf(args, *scene, camera, coarse_rounds);
    RAYSTACK_RETURN_IF_ERROR(ResumeInto(args, *scene, f, &plan, &film));
    WatchedTileSource tiles(plan);
    RAYSTACK_RETURN_IF_ERROR(LoadReference(args, f, frames, camera, &reference));
    slave::RenderStats stats;
    Status status;
    const uint64_t total = plan.total_samples();
    ConvergenceMonitor monitor(film, plan, args.stop, static_cast<uint32_t>(f), log->get(),
                               reference.get(), args.log_interval_s);
    {
      ProgressReporter progress(StrFormat("frame %zu/%zu", f + 1, frames), total, "samples",
                                args.quiet);
      std::atomic<bool> finished{false};
      preview->BeginFrame(&film, static_cast<uint32_t>(f), static_cast<uint32_t>(frames),
                          scene->integrator.spp);
      std::thread render([&] {
        status = (*engine)->RenderFrame(*scene, materials, camera, tiles, sink, &stats);
        finished.store(true);
      });
      Checkpoints checkpoints(args.checkpoint_s, FramePath(output, f, frames, ".exr"),
                              Provenance(*scene, f), &writer, args.kill_after_checkpoints,
                              args.fail_checkpoints);
      uint64_t shown = 0;
      // Polled at least as often as the convergence log asks for rows.
      const auto poll = std::chrono::microseconds(
          static_cast<int64_t>(std::min(0.1, args.log_interval_s) * 1e6));
      while (!finished.load()) {
        std::this_thread::sleep_for(poll);
        const uint64_t done = film.samples_merged();
        progress.Update(done - shown);
        shown = done;
        checkpoints.Maybe(film);
        if (!monitor.Poll()) tiles.Stop();
        preview->SetErrorEstimate(monitor.last().error_estimate);  // at each pass end
        preview->Update([&] { return tiles.Given(); });
      }
      render.join();
      progress.Update(film.samples_merged() - shown);
    }
    if (!status.ok()) {
      preview->EndFrame(std::numeric_limits<double>::quiet_NaN());
      return status;
    }
    image::ImageLayers resolved = writer.TakeSpare();
    film.ResolveInto(&resolved);
    monitor.Finish(resolved);
    preview->SetErrorEstimate(monitor.last().error_estimate);  // the last pass's
    preview->EndFrame(stats.rays_per_second);
    ReportStop(args, monitor);
    Expected<std::string> exr = WriteFrame(args, *scene, f, film, std::move(resolved), &writer);
    if (!exr.ok()) return exr.status();
    if (!args.quiet) std::printf("frame %zu: %s\n", f, stats.ToText().c_str());
    stats_json += stats.ToJson();
    if (f + 1 < frames) stats_json += ",";
  }
  RAYSTACK_RETURN_IF_ERROR(writer.Finish());
  RAYSTACK_RETURN_IF_ERROR(WriteStats(args.stats, stats_json + "]\n"));
  preview->Finish();
  return OkStatus();
}

// ---------------------------------------------------------------------------------------------
// Under mpirun with more than one rank: rank 0 is the master (tiles, film, output), ranks 1..N
// the slaves (a render engine each). Every rank reads the scene file; only slaves open the
// store.

std::string FiguresJson(size_t frame, const FrameFigures& f) {
  std::string s = StrFormat("{\n  \"frame\": %zu,\n  \"seconds\": %g,\n  \"imbalance\": %g,"
                            "\n  \"utilisation\": %g,\n  \"slaves\": [",
                            frame, f.seconds, f.imbalance(), f.utilisation());
  for (size_t i = 0; i < f.slaves.size(); ++i) {
    const SlaveFigures& x = f.slaves[i];
    s += StrFormat("%s\n    {\"rank\": %d, \"seconds\": %g, \"rays\": %llu, \"samples\": %llu, "
                   "\"tiles\": %llu, \"blocks_loaded\": %llu, \"blocks_distinct\": %llu, "
                   "\"bytes_read\": %llu, \"bytes_from_peers\": %llu, \"bytes_to_peers\": %llu, "
                   "\"bytes_to_master\": %llu, \"pixel_bytes\": %llu, "
                   "\"bytes_from_master\": %llu, \"ray_threads\": %u, \"busy_seconds\": %g, "
                   "\"fetches\": %llu, \"fetch_wait_seconds\": %g, \"fetch_runs\": %llu, "
                   "\"ray_cpu_seconds\": %g, \"loader_cpu_seconds\": %g, "
                   "\"process_cpu_seconds\": %g, \"tile_wait_seconds\": %g, "
                   "\"block_wait_seconds\": %g, \"engine_seconds\": %g, \"direct_reads\": %s}",
                   i ? "," : "", x.rank, x.done.seconds,
                   static_cast<unsigned long long>(x.done.rays),
                   static_cast<unsigned long long>(x.done.samples),
                   static_cast<unsigned long long>(x.done.tiles),
                   static_cast<unsigned long long>(x.done.blocks_loaded),
                   static_cast<unsigned long long>(x.done.blocks_distinct),
                   static_cast<unsigned long long>(x.done.bytes_read),
                   static_cast<unsigned long long>(x.done.bytes_from_peers),
                   static_cast<unsigned long long>(x.done.bytes_to_peers),
                   static_cast<unsigned long long>(x.bytes_received),
                   static_cast<unsigned long long>(x.pixel_bytes),
                   static_cast<unsigned long long>(x.bytes_sent), x.done.ray_threads,
                   x.done.busy_seconds, static_cast<unsigned long long>(x.done.fetches),
                   x.done.fetch_wait_seconds, static_cast<unsigned long long>(x.done.fetch_runs),
                   x.done.ray_cpu_seconds, x.done.loader_cpu_seconds, x.done.process_cpu_seconds,
                   x.done.tile_wait_seconds, x.done.block_wait_seconds, x.done.engine_seconds,
                   x.done.flags & wire::kFrameDoneDirectReads ? "true" : "false");
  }
  return s + "\n  ]\n}";
}

Status RunMaster(const Args& args, const render::Scene& scene, transport::Transport* net,
                 ConvergenceLog* log, bool coarse_rounds) {
  const std::string output = OutputOf(args, scene);
  const size_t frames = scene.cameras.size();
  MasterOptions options;
  options.lost_after = std::chrono::milliseconds(static_cast<int64_t>(args.lost_after_s * 1000));
  MasterNode master(net, options);
  Expected<preview::LivePreview> preview = preview::LivePreview::Start(args.preview);
  if (!preview.ok()) {
    master.Shutdown(1);
    return preview.status();
  }
  // The tiles each slave has been given this frame (the preview leaves out the finished ones).
  const auto assigned = [&] {
    std::vector<preview::RankTiles> ranks;
    std::vector<std::vector<render::Tile>> by_slave = master.TilesAssigned();
    for (size_t i = 0; i < by_slave.size(); ++i)
      ranks.push_back({static_cast<int>(i) + 1, std::move(by_slave[i])});
    return ranks;
  };
  FrameWriter writer(!args.quiet);
  std::string json = "[\n";
  std::unique_ptr<render::Film> reused_film;  // FilmFor
  std::unique_ptr<image::ImageLayers> reference;  // LoadReference
  for (size_t f = 0; f < frames; ++f) {
    const render::Camera camera(scene.cameras[f]);
    render::Film& film = FilmFor(camera, &reused_film);
    render::FramePlan plan = PlanOf(args, scene, camera, coarse_rounds);
    Status status = ResumeInto(args, scene, f, &plan, &film);
    const uint64_t total = plan.total_samples();
    if (status.ok()) status = LoadReference(args, f, frames, camera, &reference);
    if (!status.ok()) {
      master.Shutdown(1);
      return status;
    }
    ConvergenceMonitor monitor(film, plan, args.stop, static_cast<uint32_t>(f), log,
                               reference.get(), args.log_interval_s);
    FrameFigures figures;
    {
      ProgressReporter progress(StrFormat("frame %zu/%zu", f + 1, frames), total, "samples",
                                args.quiet);
      uint64_t shown = 0;
      Checkpoints checkpoints(args.checkpoint_s, FramePath(output, f, frames, ".exr"),
                              Provenance(scene, f), &writer, args.kill_after_checkpoints,
                              args.fail_checkpoints);
      preview->BeginFrame(&film, static_cast<uint32_t>(f), static_cast<uint32_t>(frames),
                          scene.integrator.spp);
      status = master.RunFrame(static_cast<uint32_t>(f), plan, &film, [&] {
                                 const uint64_t done = film.samples_merged();
                                 progress.Update(done - shown);
                                 shown = done;
                                 checkpoints.Maybe(film);
                                 const bool go_on = monitor.Poll();
                                 preview->SetErrorEstimate(monitor.last().error_estimate);
                                 preview->Update(assigned);
                                 return go_on;
                               },
                               &figures);
    }
    image::ImageLayers resolved = writer.TakeSpare();
    if (status.ok()) {
      film.ResolveInto(&resolved);
      monitor.Finish(resolved);
      preview->SetErrorEstimate(monitor.last().error_estimate);  // the last pass's
      ReportStop(args, monitor);
    }
    uint64_t rays = 0;
    for (const SlaveFigures& s : figures.slaves) rays += s.done.rays;
    preview->EndFrame(status.ok() && figures.seconds > 0 ? static_cast<double>(rays) / figures.seconds
                                                         : std::numeric_limits<double>::quiet_NaN());
    Expected<std::string> exr =
        status.ok() ? WriteFrame(args, scene, f, film, std::move(resolved), &writer)
                    : Expected<std::string>(status);
    if (!exr.ok()) {  // every rank ends, none is left waiting
      master.Shutdown(1);
      return exr.status();
    }
    if (!args.quiet) {
      std::printf("frame %zu: %d slaves, %.3f s, imbalance %.3f, utilisation %.3f\n", f,
                  net->size() - 1, figures.seconds, figures.imbalance(), figures.utilisation());
      for (const SlaveFigures& s : figures.slaves) {
        if (s.dropped) {
          std::printf("  rank %d: dropped (%s)\n", s.rank, s.failure.c_str());
          continue;
        }
        // The peers' part only where there was one (--blocks rem).
        const std::string peers =
            s.done.fetches + s.done.bytes_to_peers == 0
                ? std::string()
                : StrFormat(" (%.1f MB from peers in %llu runs, %llu requests, %.3f s waiting; "
                            "%.1f MB to peers)",
                            static_cast<double>(s.done.bytes_from_peers) / 1e6,
                            static_cast<unsigned long long>(s.done.fetch_runs),
                            static_cast<unsigned long long>(s.done.fetches),
                            s.done.fetch_wait_seconds,
                            static_cast<double>(s.done.bytes_to_peers) / 1e6);
        std::printf("  rank %d: %.3f s (ray threads busy %.3f s; CPU: process %.3f s, ray threads "
                    "%.3f s, loader %.3f s), %llu rays, %llu tiles, %llu "
                    "blocks loaded (%llu distinct), %.1f MB of blocks (%s reads)%s, %.1f MB sent "
                    "to the master\n",
                    s.rank, s.done.seconds, s.done.busy_seconds, s.done.process_cpu_seconds,
                    s.done.ray_cpu_seconds, s.done.loader_cpu_seconds,
                    static_cast<unsigned long long>(s.done.rays),
                    static_cast<unsigned long long>(s.done.tiles),
                    static_cast<unsigned long long>(s.done.blocks_loaded),
                    static_cast<unsigned long long>(s.done.blocks_distinct),
                    static_cast<double>(s.done.bytes_read) / 1e6,
                    s.done.flags & wire::kFrameDoneDirectReads ? "direct" : "buffered", peers.c_str(),
                    static_cast<double>(s.bytes_received) / 1e6);
      }
    }
    json += FiguresJson(f, figures) + (f + 1 < frames ? ",\n" : "\n");
  }
  if (const Status written = writer.Finish(); !written.ok()) {
    master.Shutdown(1);
    return written;
  }
  if (!master.Shutdown(0)) LOG_WARNING("master", "a slave did not acknowledge the end of the job");
  RAYSTACK_RETURN_IF_ERROR(WriteStats(args.stats, json + "]\n"));
  preview->Finish();
  return OkStatus();
}

// --blocks auto: rem when each slave's share of the store (stored bytes) fits in half of its
// cache budget, leaving the other half for decoded blocks; otherwise loc. Every rank decides
// the same from the same inputs.
bool UseRemoteBlocks(const Args& args, const store::StoreReader& store, int slaves,
                     std::string* why) {
  uint64_t stored = 0;
  for (const store::BlockEntry& e : store.blocks()) stored += e.stored_bytes;
  const uint64_t share = stored / static_cast<uint64_t>(slaves);
  const bool fits = share <= args.engine.cache_bytes / 2;
  *why = StrFormat("store %.1f MB on disk, %.1f MB per slave's share, %.1f MiB cache per slave",
                   static_cast<double>(stored) / 1e6, static_cast<double>(share) / 1e6,
                   static_cast<double>(args.engine.cache_bytes) / kMiB);
  if (args.blocks == "rem") return true;
  if (args.blocks == "loc") return false;
  return fits;
}

Status RunSlave(const Args& args, const render::Scene& scene, transport::Transport* net) {
  Expected<std::unique_ptr<store::StoreReader>> store = store::StoreReader::Open(scene.store);
  if (store.ok()) {  // before any block is read (PeerBlocks reads this slave's share)
    // Each slave decides for its own machine; the master prints each one's reads per frame.
    std::string reads;
    const Status s = slave::ChooseReads(args.direct_io, args.engine.cache_bytes, store->get(), &reads);
    if (!s.ok()) store = s;
  }
  std::unique_ptr<slave::PeerBlocks> peers;
  slave::EngineOptions options = args.engine;
  const bool faulty = args.fault_rank == 0 || args.fault_rank == net->rank();
  if (faulty) options.faults.fail_read = args.fail_read;
  std::string why;
  if (store.ok() && UseRemoteBlocks(args, **store, net->size() - 1, &why)) {
    peers = std::make_unique<slave::PeerBlocks>(net, **store, options.faults);
    // The share this slave keeps for its peers counts against its budget.
    if (peers->owned_bytes() >= options.cache_bytes)
      store = Status::Error(StrFormat("--blocks rem: this slave's share of the store (%.1f MiB) "
                                      "does not fit its --cache-mb (%.1f MiB); use --blocks loc "
                                      "or more slaves", static_cast<double>(peers->owned_bytes()) / kMiB,
                                      static_cast<double>(options.cache_bytes) / kMiB));
    else
      options.cache_bytes -= peers->owned_bytes();
  }
  Expected<std::unique_ptr<slave::RenderEngine>> engine =
      store.ok() ? slave::RenderEngine::Create(**store, options, peers.get())
                 : Expected<std::unique_ptr<slave::RenderEngine>>(store.status());
  if (!engine.ok()) {  // tell the master, which reports it and ends the job on every rank
    const Status s = engine.status();
    (void)net->Send(0, wire::EncodeError(static_cast<uint32_t>(net->rank()), s.message()));
    // The others go on without it: wait for the end of the job (and acknowledge it).
    slave::SlaveNode waiting(net, nullptr);
    return waiting.WaitForShutdown().ok() ? OkStatus() : s;
  }
  const render::MaterialTable materials = render::MaterialTable::Build((*store)->materials(), scene);
  slave::NodeFaults faults;
  if (faulty) faults = {args.kill_after_tiles, args.stall_after_tiles, args.stall_s};
  slave::SlaveNode node(net, engine->get(), peers.get(), faults);
  for (size_t f = 0; f < scene.cameras.size(); ++f) {
    const render::Camera camera(scene.cameras[f]);
    slave::RenderStats stats;
    const Status s = node.RunFrame(static_cast<uint32_t>(f), scene, materials, camera, &stats);
    if (!s.ok()) {
      // The master has been told (or told us), and the others go on without this slave: wait
      // for the end of the job, and acknowledge it, so every rank ends cleanly.
      return node.WaitForShutdown().ok() ? OkStatus() : s;
    }
  }
  Expected<uint32_t> reason = node.WaitForShutdown();
  if (!reason.ok()) return reason.status();
  return OkStatus();
}

Status RunDistributed(const Args& args, transport::Transport* net) {
  Expected<render::Scene> scene = LoadSceneFor(args);
  if (!scene.ok()) {
    // Every rank reads the same scene file, so usually all fail here at once: the master ends
    // the job on every rank and reports; a slave tells it and waits for that end (a slave
    // alone without the file, on another host, is dropped and the others go on). Not
    // MPI_Abort from each slave: several at once left mpirun hung or crashed.
    if (net->rank() == 0) {
      MasterNode(net).Shutdown(1);
      return scene.status();
    }
    (void)net->Send(0, wire::EncodeError(static_cast<uint32_t>(net->rank()),
                                         scene.status().message()));
    slave::SlaveNode waiting(net, nullptr);
    return waiting.WaitForShutdown().ok() ? OkStatus() : scene.status();
  }
  if (net->rank() == 0) {
    Expected<std::unique_ptr<ConvergenceLog>> log = OpenLog(args);
    Status s = log.ok() ? CheckMemory(*scene, 0) : log.status();
    if (s.ok()) s = CheckOutputs(*scene, OutputOf(args, *scene), args.png, args.checkpoint_s > 0);
    if (s.ok()) s = CheckReferences(*scene, args.reference);
    if (!s.ok()) {  // before the slaves start a frame
      MasterNode(net).Shutdown(1);
      return s;
    }
    // The master reads the store's index when it can (it need not: the slaves read the store),
    // to log the slaves' block mode and to plan the first pass.
    Expected<std::unique_ptr<store::StoreReader>> store = store::StoreReader::Open(scene->store);
    if (store.ok() && !args.quiet) {  // which block mode the slaves use, and why
      std::string why;
      const bool rem = UseRemoteBlocks(args, **store, net->size() - 1, &why);
      std::printf("blocks: %s (--blocks %s; %s)\n", rem ? "rem" : "loc", args.blocks.c_str(),
                  why.c_str());
    }
    std::string why;
    const bool coarse_rounds = CoarseRounds(args, store.ok() ? store->get() : nullptr, &why);
    LogFirstPass(args, coarse_rounds, why);
    return RunMaster(args, *scene, net, log->get(), coarse_rounds);
  }
  return RunSlave(args, *scene, net);
}

}  // namespace

int RenderCommand(int argc, char** argv) {
  Args args;
  bool help = false;
  Status s = ParseArgs(argc, argv, &args, &help);
  if (help) {
    std::fputs(kUsage, stdout);
    return 0;
  }
  if (!s.ok()) {
    std::fprintf(stderr, "raystack render: %s\n", s.message().c_str());
    return 2;
  }
  if (args.quiet) SetLogLevel(LogLevel::kWarning);  // -q: warnings and errors only
  if (mpi::LaunchedByMpirun()) {
    Expected<std::unique_ptr<mpi::MpiTransport>> net = mpi::MpiTransport::Init(&argc, &argv);
    if (!net.ok()) {
      std::fprintf(stderr, "raystack render: %s\n", net.status().message().c_str());
      return 1;
    }
    if ((*net)->size() > 1) {
      const int rank = (*net)->rank();
      if (rank > 0) args.quiet = true;  // the master reports
      s = RunDistributed(args, net->get());
      if (!s.ok()) {
        std::fprintf(stderr, "raystack render (rank %d): %s\n", rank, s.message().c_str());
        // The master has ended the job on every rank; a slave whose master did not answer
        // ends it the hard way rather than leave the others waiting.
        if (rank > 0) (*net)->Abort(1);
      }
      if ((*net)->rank_died()) mpi::MpiTransport::ExitWithoutFinalize(s.ok() ? 0 : 1);
      return s.ok() ? 0 : 1;
    }
    // mpirun -np 1: one process plays both roles, as without mpirun.
  }
  s = Run(args);
  if (!s.ok()) {
    std::fprintf(stderr, "raystack render: %s\n", s.message().c_str());
    return 1;
  }
  return 0;
}

}  // namespace raystack::master
