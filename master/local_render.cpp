#include "master/local_render.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <mutex>
#include <new>
#include <string>
#include <thread>
#include <vector>

#include "common/base/byte_sizes.h"
#include "common/base/interrupt.h"
#include "common/base/log.h"
#include "common/base/progress.h"
#include "common/render/camera.h"
#include "common/render/film.h"
#include "common/render/material_table.h"
#include "common/store/store_reader.h"
#include "master/checkpoints.h"
#include "master/convergence_monitor.h"
#include "master/frame_steps.h"
#include "master/stats_file.h"
#include "master/frame_writer.h"
#include "master/output_lock.h"
#include "master/preflight.h"
#include "master/preview/live_preview.h"
#include "master/provenance.h"
#include "slave/direct_reads.h"
#include "slave/render_engine.h"
#include "slave/tile_source.h"

namespace raystack::master {
namespace {

// The frame plan's tiles, as PlanTileSource, remembering the latest handed to each ray thread
// (the live preview shows those still in flight; a thread holds its current tile and the next,
// and the preview scans each listed tile's pixels on every refresh).
class WatchedTileSource final : public slave::TileSource {
 public:
  static constexpr size_t kKeptPerThread = 4;
  explicit WatchedTileSource(const render::FramePlan& plan) : tiles_(plan) {}
  bool Next(uint32_t thread, slave::Tile* tile) override {
    if (!tiles_.Next(thread, tile)) return false;
    std::lock_guard lock(mu_);
    if (thread >= given_.size()) given_.resize(thread + 1);
    std::vector<render::Tile>& mine = given_[thread];
    if (mine.size() >= kKeptPerThread) mine.erase(mine.begin());
    mine.push_back(*tile);
    return true;
  }
  std::vector<preview::RankTiles> Given() const {
    std::lock_guard lock(mu_);
    preview::RankTiles all{0, {}, {}};
    for (const std::vector<render::Tile>& mine : given_) all.tiles.insert(all.tiles.end(), mine.begin(), mine.end());
    return {all};
  }
  void Stop() { tiles_.Stop(); }  // a stop rule holds

 private:
  slave::PlanTileSource tiles_;
  mutable std::mutex mu_;
  std::vector<std::vector<render::Tile>> given_;  // by ray thread
};

}  // namespace

Status RenderLocally(const RenderArgs& args) {
  Expected<render::Scene> scene = LoadSceneFor(args);
  if (!scene.ok()) return scene.status();
  const std::string output = OutputOf(args, *scene);
  const size_t frames = scene->cameras.size();
  const FrameRange range = FramesOf(args, *scene);
  RAYSTACK_RETURN_IF_ERROR(CheckMemory(*scene, 0));  // the film alone, before the store is read
  RAYSTACK_RETURN_IF_ERROR(CheckOutputOf(args, *scene));
  WarnIfCheckpointsKeepLittle(args, *scene);
  WarnIfFrameSizesDiffer(*scene, range);
  if (!args.threads_given) WarnOfIdleCores(1);
  // Held to the end of the job; named from frame 0's file ("out" and "out.exr" are one).
  Expected<OutputLock> output_lock = OutputLock::Take(FrameExrPath(args, *scene, 0), range.begin, range.end);
  if (!output_lock.ok()) return output_lock.status();
  Expected<std::optional<OutputLock>> stats_lock = LockStats(args);  // held to the end too
  if (!stats_lock.ok()) return stats_lock.status();
  RAYSTACK_RETURN_IF_ERROR(CheckNoUnfinishedFrame(args, *scene));
  RAYSTACK_RETURN_IF_ERROR(CheckReferences(*scene, args.reference, range));
  Expected<std::unique_ptr<ConvergenceLog>> log = OpenLog(args);
  if (!log.ok()) return log.status();

  Expected<std::unique_ptr<store::StoreReader>> store = OpenSceneStore(*scene);
  if (!store.ok()) return store.status();
  (void)StoreChecksumAtStart(scene->store);  // the store this run renders, whatever replaces it
  // With what its engine will hold: its blocks, and --mode bvh's tree.
  const EngineMemory engine_memory = EngineMemoryOf(args.engine, **store);
  RAYSTACK_RETURN_IF_ERROR(
      CheckMemory(*scene, engine_memory.bytes, engine_memory.what, engine_memory.advice));
  std::string reads;
  RAYSTACK_RETURN_IF_ERROR(
      slave::ChooseReads(args.direct_io, args.engine.cache_bytes, store->get(), &reads));
  if (!args.quiet) std::printf("reads: %s\n", reads.c_str());
  if (!args.quiet && (args.engine.mode == slave::TraceMode::kIncore ||
                      args.engine.mode == slave::TraceMode::kBvh))
    // The frame's progress stays at 0 meanwhile: say why (a user waited 47 s on "0.0%").
    std::printf("loading every block first (--mode %s: %s decoded%s), then rendering\n",
                args.engine.mode == slave::TraceMode::kBvh ? "bvh" : "incore",
                MiB((*store)->summary().raw_bytes).c_str(),
                args.engine.mode == slave::TraceMode::kBvh ? ", and the BVH over them" : "");
  for (const std::string& option : args.slave_options)
    LOG_WARNING("render", "%s has no effect in one process: it is for the slaves of an mpirun "
                "job (mpirun -np N+1)", option.c_str());
  slave::EngineOptions options = args.engine;
  options.faults.fail_read = args.fail_read;  // the one process reads the blocks itself
  Expected<std::unique_ptr<slave::RenderEngine>> engine =
      slave::RenderEngine::Create(**store, options);
  if (!engine.ok()) return engine.status();
  const render::MaterialTable materials =
      render::MaterialTable::Build((*store)->materials(), *scene);
  WarnIfUnlit(*scene, materials, **store);
  Expected<preview::LivePreview> preview = preview::LivePreview::Start(args.preview);
  if (!preview.ok()) return preview.status();
  // From here a failure is also said on the page, for the hold time.
  const auto failed = [&](Status why) {
    preview->Fail(why);
    return why;
  };

  std::string why;
  const bool coarse_rounds = CoarseRounds(args, store->get(), 0, &why);
  LogFirstPass(args, coarse_rounds, why);
  StatsFile stats_file(args.stats);
  const InterruptsHeld held;  // to the last write (declared before `writer`: outlives it)
  FrameWriter writer(!args.quiet, args.fail_writes, FrameWriter::kRetrySeconds, args.slow_writes_s);
  std::unique_ptr<render::Film> reused_film;  // FilmFor
  std::unique_ptr<image::ImageLayers> reference;  // LoadReference
  SequenceProgress sequence(range, args.quiet);
  for (size_t f = range.begin; f < range.end; ++f) {
    WarnIfStoreReplaced(scene->store);
    const render::Camera camera(scene->cameras[f]);
    const std::string exr_path = FrameExrPath(args, *scene, f);  // its image, checkpoints too
    render::Film& film = FilmFor(camera, &reused_film);
    render::FilmSink sink(&film);
    render::FramePlan plan = PlanOf(args, *scene, camera, coarse_rounds);
    if (Status s = ResumeInto(args, *scene, f, &plan, &film); !s.ok()) return failed(std::move(s));
    WatchedTileSource tiles(plan);
    if (Status s = LoadReference(args, f, frames, camera, &reference); !s.ok())
      return failed(std::move(s));
    slave::RenderStats stats;
    Status status;
    const uint64_t total = plan.samples_to_render();  // less what --resume kept
    ConvergenceMonitor monitor(film, plan, args.stop, static_cast<uint32_t>(f), log->get(),
                               reference.get(), args.log_interval_s);
    const AfterInterrupt interrupted = [&](const std::string& said) {
      preview->Interrupted(said);
      (void)stats_file.Finish();  // a stream's array closed: the process ends with _Exit
    };
    EndIfInterruptedBetweenFrames(f, range, &writer, interrupted);
    {
      ProgressReporter progress(FrameTitle(f, frames), total, "samples",
                                args.quiet);
      // The frame's end wakes this thread at once: a sleep of `poll` here cost every frame up to
      // 100 ms after its last ray (a 8x8 image took 0.11 s, 0.01 s now).
      std::mutex finish_mutex;
      std::condition_variable finish_cv;
      bool finished = false;
      preview->BeginFrame(&film, static_cast<uint32_t>(f), static_cast<uint32_t>(frames),
                          scene->integrator.spp, plan.total_samples() - total,
                          static_cast<uint32_t>(range.end - 1));
      std::thread render([&] {
        // An exception must not leave this thread (std::terminate): it fails the frame.
        Status s;
        try {
          render::Scene copy;
          s = (*engine)->RenderFrame(render::SceneOfFrame(*scene, f, &copy), materials, camera,
                                     tiles, sink, &stats);
        } catch (...) {  // nothing allocated here (status.h): said in full after the join
          s = Status::Error(kOutOfMemory);
        }
        const std::lock_guard lock(finish_mutex);
        status = std::move(s);
        finished = true;
        finish_cv.notify_one();
      });
      // An exception out of the loop below (out of memory as a checkpoint or the monitor takes
      // an image) must not destroy the running thread, which is std::terminate ("terminate
      // called without an active exception", exit 134, the output's lock left): the frame is
      // stopped and its thread joined first.
      struct StopAndJoin {
        std::thread& thread;
        WatchedTileSource& tiles;
        ~StopAndJoin() {
          if (!thread.joinable()) return;
          tiles.Stop();
          thread.join();
        }
      } stop_and_join{render, tiles};
      Checkpoints checkpoints(args.checkpoint_s, exr_path,
                              Provenance(*scene, f), &writer, args.kill_after_checkpoints,
                              args.fail_checkpoints);
      checkpoints.AlsoPng(FramePngPath(args, *scene, f), args.exposure);
      uint64_t shown = 0;
      // Polled at least as often as the convergence log asks for rows and checkpoints are due,
      // and often enough for --time-limit to stop within 2% of it (a researcher's 0.15 s limit
      // stopped at 0.24 s, on the 0.1 s poll).
      double poll_s = std::min(0.1, args.log_interval_s);
      if (args.stop.time_limit_s > 0) poll_s = std::min(poll_s, std::max(0.001, args.stop.time_limit_s / 50));
      // A pass's end is measured at the poll after it: with a convergence log, often (the check
      // is a counter; a measure only when a pass ended), so a small frame's pass 1 row is not
      // pass 2's image (a researcher's 128 x 128 logs had the two rows alike).
      if (*log) poll_s = std::min(poll_s, 0.005);
      if (args.checkpoint_s > 0) poll_s = std::max(0.001, std::min(poll_s, args.checkpoint_s));
      const auto poll = std::chrono::microseconds(static_cast<int64_t>(poll_s * 1e6));
      for (;;) {
        {
          std::unique_lock lock(finish_mutex);
          if (finish_cv.wait_for(lock, poll, [&] { return finished; })) break;
        }
        if (const int signal = InterruptSignal())
          EndInterrupted(signal, &checkpoints, film, exr_path, plan.spp(),
                         interrupted);
        const uint64_t done = film.samples_merged();
        progress.Update(done - shown);
        shown = done;
        checkpoints.Maybe(film, plan.spp());
        if (!monitor.Poll()) tiles.Stop();
        preview->SetErrorEstimate(monitor.last().error_estimate);  // at each pass end
        preview->Update([&] { return tiles.Given(); });
      }
      render.join();
      status = ExplainShortFailure(status);
      progress.Update(film.samples_merged() - shown);
      if (!status.ok()) {
        progress.Abandon();
        status = KeepFrameSoFar(status, &checkpoints, film, exr_path,
                                plan.spp());
      }
    }
    if (!status.ok()) return failed(std::move(status));
    image::ImageLayers resolved = writer.TakeSpare();
    film.ResolveInto(&resolved);
    monitor.Finish(resolved);
    preview->SetErrorEstimate(monitor.last().error_estimate);  // the last pass's
    if (monitor.stopped()) preview->SetNote("stopped: " + monitor.stop_reason());
    preview->EndFrame(stats.rays_per_second);
    ReportStop(args, monitor);
    // The frame's record goes into --stats once its image is written.
    std::string record = stats.ToJson(FrameRecordJson(f, exr_path, camera.width(),
                                                      camera.height(), plan.spp(),
                                                      monitor.stopped() ? monitor.stop_reason() : "",
                                                      plan.total_samples() - total));
    Expected<std::string> exr = WriteFrame(args, *scene, f, film, std::move(resolved),
                                           monitor.stopped() ? monitor.stop_reason() : std::string(),
                                           total, &writer,
                                           [&stats_file, record = std::move(record)] { stats_file.Append(record); });
    if (!exr.ok()) return failed(exr.status());
    if (!args.quiet) std::printf("frame %zu: %s\n", f, stats.ToText().c_str());
    sequence.FrameDone(f, total > 0);
  }
  if (Status s = writer.Finish(); !s.ok()) return failed(std::move(s));  // the last frame's write
  if (Status s = stats_file.Finish(); !s.ok()) return failed(std::move(s));
  if (*log)
    if (Status s = (*log)->Close(); !s.ok()) return failed(std::move(s));
  preview->Finish();
  return OkStatus();
}

}  // namespace raystack::master
