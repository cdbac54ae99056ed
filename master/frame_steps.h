#pragma once
// The steps of `raystack render` that the one-process run (local_render.h) and the master of a
// distributed job (distributed_render.h) share: the scene with the command line's overrides,
// each frame's film, plan, reference and resumed pixels, its images, and what a signal does.

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "common/base/status.h"
#include "common/image/image_layers.h"
#include "common/render/camera.h"
#include "common/render/film.h"
#include "common/render/frame_plan.h"
#include "common/render/material_table.h"
#include "common/render/scene.h"
#include "common/store/store_reader.h"
#include "master/checkpoints.h"
#include "master/convergence_monitor.h"
#include "master/frame_writer.h"
#include "master/output_lock.h"
#include "master/preflight.h"
#include "master/render_args.h"

namespace raystack::master {

// A frame a stopped run left unfinished (its EXR says "partial") is not overwritten by a run
// without --resume: an operator lost 44,592 finished pixels that way, without a word. After the
// output's lock is taken, so that a render still writing it is named as such instead.
Status CheckNoUnfinishedFrame(const RenderArgs& args, const render::Scene& scene);

// The output the images are named from: --output, else the scene's.
std::string OutputOf(const RenderArgs& args, const render::Scene& scene);
// Frame f's name in progress lines: "frame 1 (2 of 3)", "frame 0" alone. Frames are counted
// from 0 as in the file names (out-1.exr), the figures and the convergence log; the progress
// said "frame 2/3" of that frame.
std::string FrameTitle(size_t f, size_t frames);
// --stats' lock, held for the job (two jobs' records in one file made it unreadable); none
// without --stats or for a stream (a pipe, the standard output). On the file a link names.
Expected<std::optional<OutputLock>> LockStats(const RenderArgs& args);
// CheckOutputs (preflight.h) for OutputOf, its errors prefixed by where the output was given
// ("--output", or the scene file's "output" key); and --stats' file (none of the job's images).
Status CheckOutputOf(const RenderArgs& args, const render::Scene& scene);
// The scene's store, its errors prefixed by the scene file and key, with what to do when the
// path holds no store at all (not converted yet, a model file, an empty folder).
Expected<std::unique_ptr<store::StoreReader>> OpenSceneStore(const render::Scene& scene);
// The scene file, with the command line's overrides; --frames checked against its cameras.
Expected<render::Scene> LoadSceneFor(const RenderArgs& args);
// The cameras this run renders (--frames, clamped to the scene's list by LoadSceneFor's check).
FrameRange FramesOf(const RenderArgs& args, const render::Scene& scene);
// A scene that can only come out black (no point light, nothing emissive in the store's
// materials or the scene's, a black background) is most likely a mistake: say so up front.
// Also emitters that will not light as the user may think: under whitted (point lights only),
// or under path without lights.bin's list (an older store, a material emissive by the scene
// file alone), where only the rays that meet them find them.
void WarnIfUnlit(const render::Scene& scene, const render::MaterialTable& materials,
                 const store::StoreReader& store);
// The stored (compressed) bytes of every block.
uint64_t StoredBytes(const store::StoreReader& store);

// --coarse-rounds auto: the first pass's rounds sweep the frame five times, which costs nothing
// when the blocks stay in the cache and reloads them on every sweep when they do not (the
// dragon x36 with a 72 MB cache: 4.5 loads per block used instead of 1.1). `store` may be null
// (a master that cannot open it): then the rounds stay on, as for an in-core scene.
// `rem_slaves`: the slaves sharing the store's blocks under --blocks rem (0 otherwise); each
// keeps its share in its cache for its peers, so less of the cache is left for the rest.
bool CoarseRounds(const RenderArgs& args, const store::StoreReader* store, int rem_slaves,
                  std::string* why);
void LogFirstPass(const RenderArgs& args, bool rounds, const std::string& why);

// The film for the next frame: the previous frame's, cleared, when the size is the same
// (Film::Clear: a few milliseconds instead of ~20 of page faults between two frames).
render::Film& FilmFor(const render::Camera& camera, std::unique_ptr<render::Film>* film);
render::FramePlan PlanOf(const RenderArgs& args, const render::Scene& scene,
                         const render::Camera& camera, bool coarse_rounds);
// --resume: the pixels frame `f`'s checkpoint holds finished go into `film`, and the plan keeps
// only the tiles that still have a pixel to render.
Status ResumeInto(const RenderArgs& args, const render::Scene& scene, size_t f,
                  render::FramePlan* plan, render::Film* film);
// What a frame is measured against, if anything: --reference (REF-f.exr with several cameras).
// Frame f's reference into `*ref` (null without --reference), read into the memory of the frame
// before's: new memory for a 960x540 reference was ~50 ms of page faults at every frame's start.
Status LoadReference(const RenderArgs& args, size_t f, size_t frames, const render::Camera& camera,
                     std::unique_ptr<image::ImageLayers>* ref);
// --convergence-log's file, or null without it.
Expected<std::unique_ptr<ConvergenceLog>> OpenLog(const RenderArgs& args);
// Says why the frame stopped early, if a stop rule (--time-limit, --target-error) ended it.
void ReportStop(const RenderArgs& args, const ConvergenceMonitor& monitor);
// Frame f's record in --stats, as "  \"key\": value,\n" lines: its index, image, size, samples
// per pixel, why it stopped early (null: it did not), the samples --resume kept from its earlier
// image (rendered by an earlier run; all of them for a complete frame kept: an operator could not
// tell such a frame's near-zero figures from a rendered one's), and the build and host of the
// run (found by a researcher: a stats file could not be traced to its run, nor its
// entries to their frames but by position).
std::string FrameRecordJson(size_t f, const std::string& exr, int width, int height, uint32_t spp,
                            const std::string& stopped, uint64_t kept_samples);

// Queues frame `f`'s EXR (and the PNG quick look) of the resolved film `layers` to `writer`;
// returns the EXR's path, or the error of an earlier frame's write.
// `stopped`: why a stop rule ended the frame early (ConvergenceMonitor::stop_reason), or empty.
// `rendered`: the samples this run rendered of it. With none under --resume, a complete frame's
// EXR there (and its PNG) is left as it is (rewritten, every file of a sequence got a new time,
// and a compositor reloaded them all); a checkpoint with every pixel finished is written.
// `written`: called once the frame's image is on disk (on the writer's thread; at once for a
// complete frame kept as it is).
Expected<std::string> WriteFrame(const RenderArgs& args, const render::Scene& scene, size_t f,
                                 const render::Film& film, image::ImageLayers layers,
                                 const std::string& stopped, uint64_t rendered,
                                 FrameWriter* writer, std::function<void()> written = nullptr);
// Frame f's EXR (as WriteFrame names it).
std::string FrameExrPath(const RenderArgs& args, const render::Scene& scene, size_t f);
// Frame f's PNG quick-look; empty without --png.
std::string FramePngPath(const RenderArgs& args, const render::Scene& scene, size_t f);

// While it lives, SIGINT and SIGTERM are noted, not fatal: from the first frame to the last
// image written (the frame rendering is written by EndInterrupted, one rendered and queued by
// the writer; the default action would lose it mid-write).
struct InterruptsHeld {
  InterruptsHeld();
  ~InterruptsHeld();
  InterruptsHeld(const InterruptsHeld&) = delete;
  InterruptsHeld& operator=(const InterruptsHeld&) = delete;
};
// What EndIfInterruptedBetweenFrames and EndInterrupted run before the process ends, given
// what they printed (without the "raystack render: " prefix): tell the live preview, then the
// slaves.
using AfterInterrupt = std::function<void(const std::string& said)>;
// --checkpoint-s where pixels finish late (progressive passes, or tiles too large to take all
// their samples at once): checkpoints keep little for --resume until the frame's end, which a
// user found out only from an interrupted run's message. Warns, with the options that fix it.
void WarnIfCheckpointsKeepLittle(const RenderArgs& args, const render::Scene& scene);
// With several frames to render, a line after each: how many of the run's frames are done, in
// how long, and about how long the rest take at the pace so far (an animator had only each
// frame's own progress, nothing for the job).
class SequenceProgress {
 public:
  SequenceProgress(FrameRange range, bool quiet) : range_(range), quiet_(quiet) {}
  // `rendered`: the frame had samples to render (not a complete frame --resume kept).
  void FrameDone(size_t f, bool rendered);

 private:
  const FrameRange range_;
  const bool quiet_;
  size_t rendered_ = 0;
  const std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

// Cameras of different sizes in one list: a sequence usually keeps one size, and a video tool
// quietly scaled the odd frame to the first's (found by an animator). Warns, naming the first.
void WarnIfFrameSizesDiffer(const render::Scene& scene, FrameRange range);
// A signal noted before frame `frame` of `range` began to render: the frames before it are
// written (or their writes finished here), the others are not rendered, and the process ends.
void EndIfInterruptedBetweenFrames(size_t frame, FrameRange range, FrameWriter* writer,
                                   const AfterInterrupt& then = [](const std::string&) {});
// A frame that failed while it rendered (a block that cannot be read, every slave lost): its
// samples so far, if any, are written where --resume finds them, as on an interrupt, and the
// error returned says where; before, the job ended with none of them written.
Status KeepFrameSoFar(const Status& why, Checkpoints* checkpoints, const render::Film& film,
                      const std::string& path, uint32_t spp);
// SIGINT or SIGTERM while frame `frame` renders (Ctrl-C; Slurm's time limit, through mpirun,
// which sends SIGKILL a second later): writes the frame's samples so far where --resume finds
// them (the frame's EXR, with its provenance), says so, and ends the process with the shell's
// code for the signal. Without it the run left nothing, unless --checkpoint-s had written some.
// `then`: run once the frame is written and the outcome printed (tell the slaves: not before,
// since mpirun ends the job, this process included, as soon as a rank ends early).
// `sigterm_hint`: said after a SIGTERM's message (under mpirun, what else sends one).
[[noreturn]] void EndInterrupted(int signal, Checkpoints* checkpoints, const render::Film& film,
                                 const std::string& path, uint32_t spp,
                                 const AfterInterrupt& then = [](const std::string&) {},
                                 const std::string& sigterm_hint = "");

}  // namespace raystack::master
