#include "master/render_command.h"

#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <functional>
#include <limits>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "common/base/build_id.h"
#include "common/base/interrupt.h"
#include "common/base/log.h"
#include "common/base/process_names.h"
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
#include "master/output_lock.h"
#include "master/preflight.h"
#include "master/preview/live_preview.h"
#include "master/provenance.h"
#include "master/render_args.h"
#include "master/resume.h"
#include "slave/direct_reads.h"
#include "slave/peer_blocks.h"
#include "slave/render_engine.h"
#include "slave/slave_node.h"

namespace raystack::master {
namespace {

// --cache-mb counts MiB (2^20 bytes), and the messages about the cache say MiB too.
constexpr double kMiB = 1024.0 * 1024.0;

Status WriteStats(const std::string& path, const std::string& json) {
  if (path.empty()) return OkStatus();
  std::ofstream out(path);
  out << json;
  if (!out) return Status::Error(path + ": cannot write the statistics");
  return OkStatus();
}

std::string OutputOf(const RenderArgs& args, const render::Scene& scene) {
  return args.output.empty() ? scene.output : args.output;
}

// Queues frame `f`'s EXR (and the PNG quick look) of the resolved film `layers` to `writer`;
// returns the EXR's path, or the error of an earlier frame's write.
Expected<std::string> WriteFrame(const RenderArgs& args, const render::Scene& scene, size_t f,
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
Expected<render::Scene> LoadSceneFor(const RenderArgs& args) {
  Expected<render::Scene> scene = render::LoadScene(args.scene);
  if (scene.ok() && args.spp > 0) scene->integrator.spp = static_cast<int>(args.spp);
  return scene;
}

render::FramePlan PlanOf(const RenderArgs& args, const render::Scene& scene, const render::Camera& camera,
                         bool coarse_rounds) {
  return render::MakeFramePlan(camera.width(), camera.height(), args.tile_size,
                               static_cast<uint32_t>(scene.integrator.spp), args.pass_spp,
                               args.engine.pixel_order, coarse_rounds);
}

// A scene that can only come out black (no point light, nothing emissive in the store's
// materials or the scene's, a black background) is most likely a mistake: say so up front.
void WarnIfUnlit(const render::Scene& scene, const render::MaterialTable& materials) {
  const Vec3f b = scene.background;
  if (!scene.lights.empty() || materials.any_emissive() || b.x > 0 || b.y > 0 || b.z > 0) return;
  LOG_WARNING("render",
              "%s: the scene has no light (no point lights, no emissive material in the store "
              "or the scene, a black background): the image will be black",
              scene.source.c_str());
}

uint64_t StoredBytes(const store::StoreReader& store) {
  uint64_t stored = 0;
  for (const store::BlockEntry& e : store.blocks()) stored += e.stored_bytes;
  return stored;
}

// --coarse-rounds auto: the first pass's rounds sweep the frame five times, which costs nothing
// when the blocks stay in the cache and reloads them on every sweep when they do not (the
// dragon x36 with a 72 MB cache: 4.5 loads per block used instead of 1.1). `store` may be null
// (a master that cannot open it): then the rounds stay on, as for an in-core scene.
// `rem_slaves`: the slaves sharing the store's blocks under --blocks rem (0 otherwise); each
// keeps its share in its cache for its peers, so less of the cache is left for the rest.
bool CoarseRounds(const RenderArgs& args, const store::StoreReader* store, int rem_slaves,
                  std::string* why) {
  if (args.coarse_rounds != "auto") {
    *why = "--coarse-rounds " + args.coarse_rounds;
    return args.coarse_rounds == "on";
  }
  if (!store) {
    *why = "the store's size is unknown here";
    return true;
  }
  const uint64_t decoded = store->summary().raw_bytes;
  // Each slave's budget loses its share as the slaves count it: stored bytes (RunSlave).
  const uint64_t share = rem_slaves > 0 ? StoredBytes(*store) / static_cast<uint64_t>(rem_slaves) : 0;
  const uint64_t room = args.engine.cache_bytes > share ? args.engine.cache_bytes - share : 0;
  const bool fits = decoded <= room;
  *why = StrFormat("decoded blocks %.1f MB %s the %.1f MiB cache", static_cast<double>(decoded) / 1e6,
                   fits ? "fit in" : "exceed", static_cast<double>(args.engine.cache_bytes) / kMiB);
  if (share > 0)
    *why += StrFormat(" less its rem share of %.1f MiB", static_cast<double>(share) / kMiB);
  return fits;
}

void LogFirstPass(const RenderArgs& args, bool rounds, const std::string& why) {
  if (args.quiet || args.engine.pixel_order != render::PixelOrder::kPriority) return;
  std::printf("first pass: %s (%s)\n", rounds ? "5 coarse rounds" : "one sweep", why.c_str());
}

// While it lives, SIGINT and SIGTERM are noted, not fatal: from the first frame to the last
// image written (the frame rendering is written by EndInterrupted, one rendered and queued by
// the writer; the default action would lose it mid-write).
struct InterruptsHeld {
  InterruptsHeld() { HoldInterrupts(true); }
  ~InterruptsHeld() { HoldInterrupts(false); }
  InterruptsHeld(const InterruptsHeld&) = delete;
  InterruptsHeld& operator=(const InterruptsHeld&) = delete;
};

// A signal noted before frame `frame` began to render: the frames before it are written (or
// their writes finished here), the others are not rendered.
void EndIfInterruptedBetweenFrames(size_t frame, size_t frames, FrameWriter* writer,
                                   const std::function<void()>& then = [] {}) {
  const int signal = InterruptSignal();
  if (signal == 0) return;
  const Status s = writer->Finish();
  then();
  const char* name = InterruptName(signal);
  if (frame == 0)
    std::fprintf(stderr, "raystack render: interrupted (%s) before the first frame\n", name);
  else
    std::fprintf(stderr, "raystack render: interrupted (%s) as frame %zu ended: %s; frames %zu "
                 "to %zu are not rendered\n", name, frame - 1,
                 s.ok() ? "it is written" : s.message().c_str(), frame, frames - 1);
  std::fflush(nullptr);
  std::_Exit(128 + signal);
}

// SIGINT or SIGTERM while frame `frame` renders (Ctrl-C; Slurm's time limit, through mpirun,
// which sends SIGKILL a second later): writes the frame's samples so far where --resume finds
// them (the frame's EXR, with its provenance), says so, and ends the process with the shell's
// code for the signal. Without it the run left nothing, unless --checkpoint-s had written some.
// `then`: run once the frame is written (tell the slaves: not before, since mpirun ends the
// job, this process included, as soon as a rank ends early).
[[noreturn]] void EndInterrupted(int signal, Checkpoints* checkpoints, const render::Film& film,
                                 const std::string& path, uint32_t spp,
                                 const std::function<void()>& then = [] {}) {
  const char* name = InterruptName(signal);
  Expected<uint64_t> finished = checkpoints->Final(film, spp);
  then();
  const uint64_t pixels = static_cast<uint64_t>(film.width()) * static_cast<uint64_t>(film.height());
  if (!finished.ok())
    std::fprintf(stderr, "raystack render: interrupted (%s); the frame's samples so far could "
                 "not be written: %s\n", name, finished.status().message().c_str());
  else if (*finished == 0)
    std::fprintf(stderr, "raystack render: interrupted (%s): the frame so far is in %s, but no "
                 "pixel has all its %u samples yet (each pass covers every pixel a little), so "
                 "--resume would render the frame again\n", name, path.c_str(), spp);
  else
    std::fprintf(stderr, "raystack render: interrupted (%s): the frame so far is in %s, %llu of "
                 "%llu pixels with all their samples; the same command with --resume keeps those "
                 "and renders the rest\n", name, path.c_str(),
                 static_cast<unsigned long long>(*finished), static_cast<unsigned long long>(pixels));
  std::fflush(nullptr);
  std::_Exit(128 + signal);
}

// What a frame is measured against, if anything: --reference (REF-f.exr with several cameras).
// Frame f's reference into `*ref` (null without --reference), read into the memory of the frame
// before's: new memory for a 960x540 reference was ~50 ms of page faults at every frame's start.
Status LoadReference(const RenderArgs& args, size_t f, size_t frames, const render::Camera& camera,
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

Expected<std::unique_ptr<ConvergenceLog>> OpenLog(const RenderArgs& args) {
  if (args.convergence_log.empty()) return std::unique_ptr<ConvergenceLog>();
  return ConvergenceLog::Open(args.convergence_log);
}

void ReportStop(const RenderArgs& args, const ConvergenceMonitor& monitor) {
  if (monitor.stopped() && !args.quiet) std::printf("stopped: %s\n", monitor.stop_reason().c_str());
}

// --resume: the pixels frame `f`'s checkpoint holds finished go into `film`, and the plan keeps
// only the tiles that still have a pixel to render.
Status ResumeInto(const RenderArgs& args, const render::Scene& scene, size_t f,
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

Status Run(const RenderArgs& args) {
  Expected<render::Scene> scene = LoadSceneFor(args);
  if (!scene.ok()) return scene.status();
  const std::string output = OutputOf(args, *scene);
  const size_t frames = scene->cameras.size();
  RAYSTACK_RETURN_IF_ERROR(CheckMemory(*scene, 0));  // the film alone, before the store is read
  RAYSTACK_RETURN_IF_ERROR(CheckOutputs(*scene, output, args.png, args.checkpoint_s > 0));
  // Held to the end of the job; named from the output as written ("out" and "out.exr" are one).
  Expected<OutputLock> output_lock = OutputLock::Take(FramePath(output, 0, 1, ".exr"));
  if (!output_lock.ok()) return output_lock.status();
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
  WarnIfUnlit(*scene, materials);
  Expected<preview::LivePreview> preview = preview::LivePreview::Start(args.preview);
  if (!preview.ok()) return preview.status();

  std::string why;
  const bool coarse_rounds = CoarseRounds(args, store->get(), 0, &why);
  LogFirstPass(args, coarse_rounds, why);
  std::string stats_json = "[\n";
  const InterruptsHeld held;  // to the last write (declared before `writer`: outlives it)
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
    EndIfInterruptedBetweenFrames(f, frames, &writer);
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
        if (const int signal = InterruptSignal())
          EndInterrupted(signal, &checkpoints, film, FramePath(output, f, frames, ".exr"), plan.spp());
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
      if (!status.ok()) progress.Abandon();
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

// `remote_blocks`: whether the slaves read blocks from peers, where the master can tell.
Status RunMaster(const RenderArgs& args, const render::Scene& scene, transport::Transport* net,
                 ConvergenceLog* log, bool coarse_rounds, std::optional<bool> remote_blocks) {
  const std::string output = OutputOf(args, scene);
  const size_t frames = scene.cameras.size();
  MasterOptions options;
  options.lost_after = std::chrono::milliseconds(static_cast<int64_t>(args.lost_after_s * 1000));
  options.beat = true;
  options.identity = JobIdentity{BuildId(), StoreChecksum(scene.store), SceneChecksum(scene),
                                 remote_blocks};
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
  const InterruptsHeld held;  // to the last write (declared before `writer`: outlives it)
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
    EndIfInterruptedBetweenFrames(f, frames, &writer, [&] { master.Abandon(); });
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
                                 if (const int signal = InterruptSignal())
                                   EndInterrupted(signal, &checkpoints, film,
                                                  FramePath(output, f, frames, ".exr"), plan.spp(),
                                                  [&] { master.Abandon(); });
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
      if (!status.ok()) progress.Abandon();
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

// How long a slave waits without a word from the master before it takes it for gone: a lost
// master loses the job, a lost slave only time, so a slave is six times as patient as the
// master is with it (--lost-after).
std::chrono::milliseconds MasterLostAfter(const RenderArgs& args) {
  return std::chrono::milliseconds(static_cast<int64_t>(6 * args.lost_after_s * 1000));
}

// --blocks auto: rem when each slave's share of the store (stored bytes) fits in half of its
// cache budget, leaving the other half for decoded blocks; otherwise loc. Every rank decides
// the same from the same inputs.
bool UseRemoteBlocks(const RenderArgs& args, const store::StoreReader& store, int slaves,
                     std::string* why) {
  const uint64_t stored = StoredBytes(store);
  const uint64_t share = stored / static_cast<uint64_t>(slaves);
  const bool fits = share <= args.engine.cache_bytes / 2;
  *why = StrFormat("store %.1f MB on disk, %.1f MB per slave's share, %.1f MiB cache per slave",
                   static_cast<double>(stored) / 1e6, static_cast<double>(share) / 1e6,
                   static_cast<double>(args.engine.cache_bytes) / kMiB);
  if (args.blocks == "rem") return true;
  if (args.blocks == "loc") return false;
  return fits;
}

Status RunSlave(const RenderArgs& args, const render::Scene& scene, transport::Transport* net) {
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
    slave::SlaveNode waiting(net, nullptr, nullptr, {}, MasterLostAfter(args));
    return waiting.WaitForShutdown().ok() ? OkStatus() : s;
  }
  // What this slave renders, for the master to check against the others before its pixels.
  wire::Hello hello{};
  hello.ray_threads = static_cast<uint32_t>(options.threads);
  hello.flags = peers ? wire::kHelloRemoteBlocks : 0u;
  hello.store_checksum = StoreChecksum(scene.store).value_or(0);
  hello.scene_checksum = SceneChecksum(scene);
  wire::SetHelloText(hello.build, BuildId());
  wire::SetHelloText(hello.host, HostName());
  if (Status s = net->Send(0, wire::Encode(static_cast<uint32_t>(net->rank()), hello)); !s.ok())
    return s;
  const render::MaterialTable materials = render::MaterialTable::Build((*store)->materials(), scene);
  if (net->rank() == 1) WarnIfUnlit(scene, materials);  // once for the job
  slave::NodeFaults faults;
  if (faulty) faults = {args.kill_after_tiles, args.stall_after_tiles, args.stall_s};
  slave::SlaveNode node(net, engine->get(), peers.get(), faults, MasterLostAfter(args));
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

// Below this tile side, a distributed job is warned of: its tiles' round trips dominate.
constexpr int kFewestTilePixels = 8;

Status RunDistributed(const RenderArgs& args, transport::Transport* net) {
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
    slave::SlaveNode waiting(net, nullptr, nullptr, {}, MasterLostAfter(args));
    return waiting.WaitForShutdown().ok() ? OkStatus() : scene.status();
  }
  if (net->rank() == 0) {
    Expected<std::unique_ptr<ConvergenceLog>> log = OpenLog(args);
    Status s = log.ok() ? CheckMemory(*scene, 0) : log.status();
    if (s.ok()) s = CheckOutputs(*scene, OutputOf(args, *scene), args.png, args.checkpoint_s > 0);
    Expected<OutputLock> output_lock =  // held to the end of the job
        s.ok() ? OutputLock::Take(FramePath(OutputOf(args, *scene), 0, 1, ".exr"))
               : Expected<OutputLock>(s);
    if (!output_lock.ok()) s = output_lock.status();
    if (s.ok()) s = CheckReferences(*scene, args.reference);
    if (!s.ok()) {  // before the slaves start a frame
      MasterNode(net).Shutdown(1);
      return s;
    }
    // The master reads the store's index when it can (it need not: the slaves read the store),
    // to log the slaves' block mode and to plan the first pass.
    Expected<std::unique_ptr<store::StoreReader>> store = store::StoreReader::Open(scene->store);
    bool rem = false;
    if (store.ok()) {  // which block mode the slaves use, and why
      std::string why;
      rem = UseRemoteBlocks(args, **store, net->size() - 1, &why);
      if (!args.quiet)
        std::printf("blocks: %s (--blocks %s; %s)\n", rem ? "rem" : "loc", args.blocks.c_str(),
                    why.c_str());
      // Every slave would refuse its share (RunSlave) once started: say so once, before.
      const uint64_t share =
          rem ? StoredBytes(**store) / static_cast<uint64_t>(net->size() - 1) : 0;
      if (share > 0 && share >= args.engine.cache_bytes) {
        MasterNode(net).Shutdown(1);
        return Status::Error(StrFormat(
            "--blocks rem: a slave's share of the store (%.1f MiB on average over %d slaves) "
            "does not fit its --cache-mb (%.1f MiB); use --blocks loc, more slaves or a larger "
            "--cache-mb", static_cast<double>(share) / kMiB, net->size() - 1,
            static_cast<double>(args.engine.cache_bytes) / kMiB));
      }
    }
    // Each tile is a request to the master and an answer: tiles of a few pixels make the job
    // slower, not finer (--tile-size 1 under mpirun: 85x the one-process time, 320x180).
    if (args.tile_size < kFewestTilePixels)
      LOG_WARNING("master", "--tile-size %d: each tile costs a round trip to the master; tiles "
                  "under %d pixels a side make the job much slower", args.tile_size, kFewestTilePixels);
    std::string why;
    const bool coarse_rounds = CoarseRounds(args, store.ok() ? store->get() : nullptr,
                                            rem ? net->size() - 1 : 0, &why);
    LogFirstPass(args, coarse_rounds, why);
    return RunMaster(args, *scene, net, log->get(), coarse_rounds,
                     store.ok() ? std::optional<bool>(rem) : std::nullopt);
  }
  return RunSlave(args, *scene, net);
}

}  // namespace

int RenderCommand(int argc, char** argv) {
  RenderArgs args;
  bool help = false;
  Status s = ParseRenderArgs(argc, argv, &args, &help);
  if (help) {
    std::fputs(kRenderUsage, stdout);
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
      // mpirun forwards SIGINT and SIGTERM to every rank, and SIGKILL a second later: a slave
      // that died of the signal at once had mpirun end the master before it wrote anything.
      // So a slave holds it while its node runs (SlaveNode: it waits for the master's end of
      // the job, or ends a moment later if the master was not signalled); the master holds it
      // from its first frame to its last write (EndInterrupted writes the frame).
      CatchInterrupts(rank == 0);
      if (rank > 0) args.quiet = true;  // the master reports
      s = RunDistributed(args, net->get());
      if (!s.ok()) {
        std::fprintf(stderr, "raystack render (rank %d): %s\n", rank, s.message().c_str());
        // A slave whose master is gone ends alone (MPI_Abort could end a master that is only
        // cut off from this host, with its image nearly done).
        if (rank > 0 && (*net)->dead(0)) mpi::MpiTransport::ExitWithoutFinalize(1);
        // The master has ended the job on every rank; a slave whose master did not answer
        // ends it the hard way rather than leave the others waiting.
        if (rank > 0) (*net)->Abort(1);
      }
      // A rank that will not end with the job (another build's, one that did not acknowledge
      // the end) would keep mpirun waiting, under --enable-recovery forever.
      if ((*net)->rank_will_not_end()) (*net)->Abort(s.ok() ? 0 : 1);
      if ((*net)->rank_died()) mpi::MpiTransport::ExitWithoutFinalize(s.ok() ? 0 : 1);
      return s.ok() ? 0 : 1;
    }
    // mpirun -np 1: one process plays both roles, as without mpirun.
  }
  CatchInterrupts(true);
  s = Run(args);
  if (!s.ok()) {
    std::fprintf(stderr, "raystack render: %s\n", s.message().c_str());
    return 1;
  }
  return 0;
}

}  // namespace raystack::master
