#include "master/frame_steps.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "common/base/build_id.h"
#include "common/base/byte_sizes.h"
#include "common/base/interrupt.h"
#include "common/base/log.h"
#include "common/base/process_names.h"
#include "common/base/utf8.h"
#include "common/image/exr_io.h"
#include "common/base/output_file.h"
#include "common/store/format.h"
#include "master/preflight.h"
#include "master/provenance.h"
#include "master/resume.h"
#include "master/stats_file.h"

namespace raystack::master {

namespace {

// `text` as a JSON string: quotes, backslashes and control characters escaped, and each byte
// that is not part of valid UTF-8 (a path in another encoding) as \u00XX, so the file stays
// JSON (it was not, with a Latin-1 output name).
std::string JsonQuoted(const std::string& text) {
  std::string q = "\"";
  for (size_t i = 0; i < text.size();) {
    const char c = text[i];
    const size_t n = Utf8Length(text, i);
    if (n == 0 || static_cast<unsigned char>(c) < 0x20) {
      q += StrFormat("\\u%04x", static_cast<unsigned char>(c));
      ++i;
    } else if (c == '"' || c == '\\') {
      q += '\\', q += c, ++i;
    } else {
      q.append(text, i, n);
      i += n;
    }
  }
  return q + "\"";
}

}  // namespace

std::string FrameRecordJson(size_t f, const std::string& exr, int width, int height, uint32_t spp,
                            const std::string& stopped, uint64_t kept_samples) {
  return StrFormat("  \"frame\": %zu,\n  \"output\": %s,\n  \"width\": %d,\n  \"height\": %d,\n"
                   "  \"spp\": %u,\n  \"stopped\": %s,\n  \"kept_samples\": %llu,\n  \"build\": %s,\n"
                   "  \"host\": %s,\n",
                   f, JsonQuoted(exr).c_str(), width, height, spp,
                   stopped.empty() ? "null" : JsonQuoted(stopped).c_str(),
                   static_cast<unsigned long long>(kept_samples), JsonQuoted(BuildId()).c_str(),
                   JsonQuoted(HostName()).c_str());
}

std::string FrameTitle(size_t f, size_t frames) {
  return frames == 1 ? std::string("frame 0") : StrFormat("frame %zu (%zu of %zu)", f, f + 1, frames);
}

std::string OutputOf(const RenderArgs& args, const render::Scene& scene) {
  return args.output.empty() ? scene.output : args.output;
}

namespace {

// --stats: writable (found out now, not after the render: a user lost a render's figures), and
// none of the job's images (a review: `--stats t-0.exr --frames 2-3` replaced frame 0 with JSON,
// and `--stats o.exr --output o.exr` was refused as "another render").
// The image of this job (any frame's EXR or PNG) that `file` names, or "".
std::string ImageOfTheJobAt(const RenderArgs& args, const render::Scene& scene,
                            const std::string& file) {
  std::error_code ec;
  const std::filesystem::path given = std::filesystem::weakly_canonical(file, ec);
  const std::string output = OutputOf(args, scene);
  const size_t frames = scene.cameras.size();
  for (size_t f = 0; f < frames; ++f)
    for (const char* ext : {".exr", ".png"}) {
      const std::string image = FramePath(output, f, frames, ext);
      if (std::filesystem::weakly_canonical(image, ec) == given) return image;
    }
  return "";
}

Status CheckStatsTarget(const RenderArgs& args, const render::Scene& scene) {
  if (args.stats.empty()) return OkStatus();
  std::error_code dir_ec;
  if (std::filesystem::is_directory(args.stats, dir_ec))  // found only after the job, before
    return Status::Error("--stats " + args.stats + " is a folder: give a file (e.g. " +
                         (std::filesystem::path(args.stats) / "stats.json").lexically_normal().string() + ")");
  const OutputTarget target = ResolveOutputTarget(args.stats);
  if (target.stream) return OkStatus();  // a pipe, a terminal, the standard output: nothing to replace
  if (Status s = CheckWritable(target.path); !s.ok()) return Status::Error("--stats: " + s.message());
  if (const std::string image = ImageOfTheJobAt(args, scene, target.path); !image.empty())
    return Status::Error("--stats " + args.stats + " is " + image + ", an image of this job's "
                         "output: give the statistics a file of their own (e.g. stats.json)");
  return OkStatus();
}

// The convergence log is a file of its own: given the --stats file's name or an image's, the
// job refused itself as "another raystack render" (its own locks) or would have mixed them.
Status CheckLogTarget(const RenderArgs& args, const render::Scene& scene) {
  if (args.convergence_log.empty()) return OkStatus();
  std::error_code ec;
  const std::filesystem::path log = std::filesystem::weakly_canonical(args.convergence_log, ec);
  if (!args.stats.empty() && std::filesystem::weakly_canonical(args.stats, ec) == log)
    return Status::Error("--convergence-log " + args.convergence_log + " is the --stats file: give "
                         "each a file of its own (e.g. log.csv and stats.json)");
  if (const std::string image = ImageOfTheJobAt(args, scene, args.convergence_log); !image.empty())
    return Status::Error("--convergence-log " + args.convergence_log + " is " + image +
                         ", an image of this job's output: give the log a file of its own "
                         "(e.g. log.csv)");
  return OkStatus();
}

}  // namespace

Expected<std::optional<OutputLock>> LockStats(const RenderArgs& args) {
  if (args.stats.empty()) return std::optional<OutputLock>();
  const OutputTarget target = ResolveOutputTarget(args.stats);
  if (target.stream) return std::optional<OutputLock>();  // two jobs' pipes are their own
  Expected<OutputLock> lock = OutputLock::Take(target.path, 0, 1, "--stats");
  if (!lock.ok()) return lock.status();
  return std::optional<OutputLock>(std::move(*lock));
}

Status CheckOutputOf(const RenderArgs& args, const render::Scene& scene) {
  RAYSTACK_RETURN_IF_ERROR(CheckStatsTarget(args, scene));
  RAYSTACK_RETURN_IF_ERROR(CheckLogTarget(args, scene));
  const Status s = CheckOutputs(scene, OutputOf(args, scene), args.png, args.checkpoint_s > 0,
                                FramesOf(args, scene));
  if (s.ok()) return s;
  return Status::Error((args.output.empty() ? scene.source + ": output" : std::string("--output")) +
                       ": " + s.message());
}

namespace {

// Whether the partial frame at `exr` has no pixel with `spp` samples: nothing --resume would
// keep (a frame written to look at when interrupted in its first passes, or such a checkpoint).
bool NothingToResume(const std::string& exr, uint32_t spp) {
  Expected<image::ImageLayers> read = image::ReadExr(exr);
  return read.ok() && !read->samples.empty() &&
         std::none_of(read->samples.begin(), read->samples.end(), [spp](uint32_t n) { return n >= spp; });
}

}  // namespace

Status CheckNoUnfinishedFrame(const RenderArgs& args, const render::Scene& scene) {
  if (args.resume) return OkStatus();
  const FrameRange range = FramesOf(args, scene);
  const auto spp = static_cast<uint32_t>(scene.integrator.spp);
  for (size_t f = range.begin; f < range.end; ++f) {
    const std::string exr = FrameExrPath(args, scene, f);
    if (!image::IsPartialFrame(exr)) continue;
    // A plain run after one interrupted in its first passes was refused, for nothing to keep.
    if (NothingToResume(exr, spp)) {
      LOG_INFO("render", "%s: a stopped run's frame with no pixel finished, which --resume could "
               "not use: rendered from the start", exr.c_str());
      continue;
    }
    return Status::Error(exr + " holds a frame a stopped run left unfinished: --resume "
                         "continues it; to render it from the start, remove it or give "
                         "another --output");
  }
  return OkStatus();
}

Expected<std::unique_ptr<store::StoreReader>> OpenSceneStore(const render::Scene& scene) {
  Expected<std::unique_ptr<store::StoreReader>> store = store::StoreReader::Open(scene.store);
  if (store.ok()) return store;
  const std::string where = scene.source + ": store \"" + scene.store + "\": ";
  const std::string none = store::NoStoreThere(scene.store);
  if (!none.empty()) return Status::Error(where + none);
  return Status::Error(where + store.status().message());
}

namespace {

// A frame that shows nothing is most likely a mistake the user cannot see in the numbers: the
// camera looking away from the model, or inside it with the lights outside (an animator got
// all-black frames that way without a word). Counted over the pixels that have samples. A frame
// whose brightest pixel is very dim is rounded coarsely by the film's fixed-point sums, and
// below their step it is black (a researcher's lamp of 1e-15 gave a black image; 1e-10, 3%
// errors): said, with what to do.
void WarnIfFrameShowsNothing(const image::ImageLayers& layers, size_t f) {
  bool sampled = false, met = false;
  float brightest = 0;
  for (size_t i = 0; i < layers.samples.size(); ++i) {
    if (layers.samples[i] == 0) continue;
    sampled = true;
    met |= std::isfinite(layers.z[i]);
    for (int c = 0; c < 3; ++c) brightest = std::max(brightest, std::fabs(layers.rgba[4 * i + c]));
  }
  if (!sampled) return;
  constexpr float kDim = 1e-9f;  // the film's step, 2^-50, is 1e-6 of this
  const char* dim_advice = "the film sums samples in steps of 2^-50 (~9e-16), so radiance this "
                           "low is rounded coarsely or lost: scale the lights (and emission, "
                           "background) up, by a power of two to scale the image exactly";
  if (!met)
    LOG_WARNING("render", "frame %zu: no camera ray met the model (is the camera looking away "
                "from it? raystack-info STORE gives the model's bounds)", f);
  else if (brightest == 0)
    LOG_WARNING("render", "frame %zu is black: every pixel 0 (is the camera inside the model, "
                "or does no light reach what it sees? if the lights are very dim: %s)", f,
                dim_advice);
  else if (brightest < kDim)
    LOG_WARNING("render", "frame %zu is very dim (its brightest pixel %g): %s", f,
                static_cast<double>(brightest), dim_advice);
}

// A frame's image to write: its layers, how they are recorded and shown.
void FillImage(const RenderArgs& args, const render::Scene& scene, size_t f,
               const render::Film& film, image::ImageLayers layers, const std::string& stopped,
               FrameWriter::Image* out) {
  FrameWriter::Image& image = *out;
  image.exposure = args.exposure;
  image.background = f + 1 < FramesOf(args, scene).end;  // the next renders while it is written
  image.layers = std::move(layers);
  image.layers.provenance = Provenance(scene, f);
  image.layers.partial = false;  // (the layers may be a checkpoint's, reused)
  image.layers.stopped = stopped;
  WarnIfFrameShowsNothing(image.layers, f);
  // A frame stopped before its first pass covered it (a short --time-limit): its file is
  // "complete" with black holes, which a researcher took for misses.
  const size_t unsampled = static_cast<size_t>(
      std::count(image.layers.samples.begin(), image.layers.samples.end(), 0u));
  if (unsampled > 0 && !stopped.empty())
    LOG_WARNING("render", "frame %zu: %zu pixels have no sample (stopped before the first pass "
                "reached them): black in the image (A = 0, Z = +inf, as a miss)", f, unsampled);
  if (film.nonfinite_dropped() > 0)
    LOG_WARNING("render", "%llu samples with NaN or Inf radiance were dropped",
                static_cast<unsigned long long>(film.nonfinite_dropped()));
}

}  // namespace

std::string FrameExrPath(const RenderArgs& args, const render::Scene& scene, size_t f) {
  return FramePath(OutputOf(args, scene), f, scene.cameras.size(), ".exr");
}

std::string FramePngPath(const RenderArgs& args, const render::Scene& scene, size_t f) {
  return args.png ? FramePath(OutputOf(args, scene), f, scene.cameras.size(), ".png") : "";
}

Expected<std::string> WriteFrame(const RenderArgs& args, const render::Scene& scene, size_t f,
                                 const render::Film& film, image::ImageLayers layers,
                                 const std::string& stopped, uint64_t rendered,
                                 FrameWriter* writer, std::function<void()> written) {
  FrameWriter::Image image;
  image.exr = FrameExrPath(args, scene, f);
  image.written = std::move(written);
  image.png = FramePngPath(args, scene, f);
  // (A checkpoint with every pixel finished is written as the frame; a missing PNG is made
  // from the complete EXR's pixels, the EXR left as it is.)
  std::error_code ec;
  if (args.resume && rendered == 0 && !image::IsPartialFrame(image.exr)) {
    if (image.png.empty() || std::filesystem::exists(image.png, ec)) {
      if (!args.quiet) std::printf("  kept %s (complete)\n", image.exr.c_str());
      image.nothing = true;  // `written` in its turn, after the frames before it
    } else {
      image.png_only = true;
    }
  }
  if (!image.nothing) FillImage(args, scene, f, film, std::move(layers), stopped, &image);
  const std::string exr = image.exr;
  if (Status refused = writer->Write(std::move(image)); !refused.ok()) {
    // An earlier frame's image failed. The one the writer still holds may fail too (an interrupt
    // ended the first one's retries): waited for, so the error names every frame not written.
    const Status all = writer->Finish();
    return all.ok() ? refused : all;
  }
  return exr;
}

render::Film& FilmFor(const render::Camera& camera, std::unique_ptr<render::Film>* film) {
  if (*film && (*film)->width() == camera.width() && (*film)->height() == camera.height())
    (*film)->Clear();
  else
    *film = std::make_unique<render::Film>(camera.width(), camera.height());
  return **film;
}

Expected<render::Scene> LoadSceneFor(const RenderArgs& args) {
  Expected<render::Scene> scene = render::LoadScene(args.scene);
  if (scene.ok() && args.spp > 0) scene->integrator.spp = static_cast<int>(args.spp);
  if (!scene.ok()) return scene;
  const size_t cameras = scene->cameras.size();
  const size_t asked = args.last_frame == SIZE_MAX ? args.first_frame : args.last_frame;
  if (asked >= cameras)
    return Status::Error(StrFormat("--frames: the scene has %zu camera%s (%s), no frame %zu",
                                   cameras, cameras == 1 ? "" : "s",
                                   cameras == 1 ? "frame 0"
                                                : StrFormat("frames 0 to %zu", cameras - 1).c_str(),
                                   asked));
  return scene;
}

FrameRange FramesOf(const RenderArgs& args, const render::Scene& scene) {
  const size_t cameras = scene.cameras.size();
  return {std::min(args.first_frame, cameras), std::min(args.last_frame, cameras - 1) + 1};
}

render::FramePlan PlanOf(const RenderArgs& args, const render::Scene& scene,
                         const render::Camera& camera, bool coarse_rounds) {
  return render::MakeFramePlan(camera.width(), camera.height(), args.tile_size,
                               static_cast<uint32_t>(scene.integrator.spp), args.pass_spp,
                               args.engine.pixel_order, coarse_rounds);
}

namespace {

// Path tracing aims at the emitters lights.bin lists: say which emitters it cannot aim at (a
// store too full, or converted before lights.bin; emissive by the scene file alone).
void WarnIfEmittersNotAimedAt(const render::Scene& scene, const render::MaterialTable& materials,
                              const store::StoreReader& store) {
  bool stored = false;  // an emitter lights.bin lists, or would list with a newer converter
  for (size_t m = 0; m + 1 < materials.size(); ++m)
    stored = stored || (materials.Get(static_cast<uint32_t>(m)).emissive() &&
                        store::EmitsLight(store.materials()[m]));
  if (stored && (store.summary().model_flags & store::kModelEmittersUnlisted))
    LOG_WARNING("render", "%s: more emissive triangles than raystack-prep's --mem-limit listed: "
                "path tracing finds them only where rays meet them; convert again with a larger "
                "--mem-limit for far less noise", store.dir().c_str());
  else if (stored && !store.lights_listed())
    LOG_WARNING("render", "%s: converted before raystack-prep listed emitters (no %s): path "
                "tracing finds its emissive triangles only where rays meet them; convert the "
                "model again for far less noise", store.dir().c_str(), store::kLightsFile);
  std::string names;  // the first few, then how many more (a scene may have thousands)
  size_t count = 0;
  for (size_t m = 0; m + 1 < materials.size(); ++m)
    if (materials.Get(static_cast<uint32_t>(m)).emissive() &&
        !store::EmitsLight(store.materials()[m]) && ++count <= 3)
      names += (names.empty() ? "'" : ", '") + std::string(store.materials()[m].name) + "'";
  if (count > 3) names += StrFormat(" and %zu more", count - 3);
  if (count > 0)
    LOG_WARNING("render", "%s: emissive only by the scene file: %s; path tracing finds such "
                "emitters only where rays meet them (it aims at what the MTL makes emissive: "
                "give them Ke there and convert again for less noise)", scene.source.c_str(),
                names.c_str());
  if (materials.default_material().emissive())
    LOG_WARNING("render", "%s: the default material emits: path tracing finds those triangles "
                "only where rays meet them (it aims at what the MTL makes emissive)",
                scene.source.c_str());
}

}  // namespace

void WarnIfUnlit(const render::Scene& scene, const render::MaterialTable& materials,
                 const store::StoreReader& store) {
  const Vec3f b = scene.background;
  const bool path = scene.integrator.type == render::IntegratorType::kPath;
  const bool background = b.x > 0 || b.y > 0 || b.z > 0, emissive = materials.any_emissive();
  if (scene.lights.empty() && !emissive && !background) {
    LOG_WARNING("render",
                "%s: the scene has no light (no point lights, no emissive material in the store "
                "or the scene, a black background): the image will be black",
                scene.source.c_str());
    return;
  }
  if (path) {
    if (emissive) WarnIfEmittersNotAimedAt(scene, materials, store);
    return;
  }
  // Whitted lights with point lights only: a bright background lit nothing, without a word (the
  // "no light" warning took it for a light).
  const char* seen = emissive && background ? "the emissive materials and the background are"
                     : emissive             ? "the emissive materials are"
                                            : "the background is";
  if (scene.lights.empty())
    LOG_WARNING("render", "%s: the whitted integrator lights with point lights only, and the scene "
                "has none: every diffuse surface will be black (%s seen, directly and in mirrors "
                "and glass, but light nothing; the \"path\" integrator lights with them)",
                scene.source.c_str(), seen);
  else if (emissive)
    LOG_WARNING("render", "%s: the whitted integrator lights with point lights only: the emissive "
                "materials are seen, but light nothing (the \"path\" integrator lights with them)",
                scene.source.c_str());
}

uint64_t StoredBytes(const store::StoreReader& store) {
  uint64_t stored = 0;
  for (const store::BlockEntry& e : store.blocks()) stored += e.stored_bytes;
  return stored;
}

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
  if (args.engine.mode == slave::TraceMode::kIncore || args.engine.mode == slave::TraceMode::kBvh) {
    *why = StrFormat("decoded blocks %.1f MB, all in memory (--mode %s has no cache budget)",
                     static_cast<double>(decoded) / 1e6,
                     args.engine.mode == slave::TraceMode::kIncore ? "incore" : "bvh");
    return true;
  }
  // Each slave's budget loses its share as the slaves count it: stored bytes (RunSlave).
  const uint64_t share = rem_slaves > 0 ? StoredBytes(*store) / static_cast<uint64_t>(rem_slaves) : 0;
  const uint64_t room = args.engine.cache_bytes > share ? args.engine.cache_bytes - share : 0;
  const bool fits = decoded <= room;
  *why = StrFormat("decoded blocks %s %s the %s cache", MiB(decoded).c_str(),
                   fits ? "fit in" : "exceed", MiB(args.engine.cache_bytes).c_str());
  if (share > 0) *why += " less its rem share of " + MiB(share);
  return fits;
}

void LogFirstPass(const RenderArgs& args, bool rounds, const std::string& why) {
  if (args.quiet || args.engine.pixel_order != render::PixelOrder::kPriority) return;
  std::printf("first pass: %s (%s)\n", rounds ? "5 coarse rounds" : "one sweep", why.c_str());
}

InterruptsHeld::InterruptsHeld() { HoldInterrupts(true); }
InterruptsHeld::~InterruptsHeld() { HoldInterrupts(false); }

namespace {

// What makes tiles finish one by one, each with all its samples at once: one pass of every
// sample, and tiles small enough to hold them (render::kMaxTileSamples).
// The side of the largest (power of two) tile that takes all `spp` samples in one sweep; 0 when
// it would be under 4 pixels (tiny tiles cost a round trip each under mpirun: not advised).
int WholeTileSide(uint32_t spp) {
  const auto fits = [spp](uint64_t side) { return side * side * spp <= render::kMaxTileSamples; };
  int side = 1;
  while (fits(static_cast<uint64_t>(side) * 2)) side *= 2;
  return side >= 4 && fits(static_cast<uint64_t>(side)) ? side : 0;
}

std::string WholeTilesAdvice(uint32_t spp) {
  const int side = WholeTileSide(spp);
  if (side == 0)
    return StrFormat("--pass-spp %u keeps pixels as their tiles' last sweep ends (at %u samples a "
                     "pixel, a tile of 4 x 4 or more takes them in several sweeps)", spp, spp);
  return StrFormat("--pass-spp %u --tile-size %d renders whole tiles one after another, each kept "
                   "as it finishes", spp, side);
}

}  // namespace

void SequenceProgress::FrameDone(size_t f, bool rendered) {
  const size_t frames = range_.end - range_.begin, done = f + 1 - range_.begin;
  rendered_ += rendered ? 1 : 0;
  if (quiet_ || frames < 2) return;
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  const auto duration = [](double s) {
    return s < 120 ? StrFormat("%.0f s", s)
                   : s < 7200 ? StrFormat("%.0f min", s / 60) : StrFormat("%.1f h", s / 3600);
  };
  // At the pace of the frames rendered: frames --resume kept took no time (an operator was told
  // "about 0 s left" with most of the job to come).
  std::string left;
  if (done < frames && rendered_ > 0)
    left = ", about " + duration(seconds / static_cast<double>(rendered_) *
                                 static_cast<double>(frames - done)) + " left";
  std::printf("sequence: %zu of %zu frames in %s%s\n", done, frames, duration(seconds).c_str(),
              left.c_str());
}

void WarnIfFrameSizesDiffer(const render::Scene& scene, FrameRange range) {
  const render::CameraDesc& first = scene.cameras[range.begin];
  for (size_t f = range.begin + 1; f < range.end; ++f) {
    const render::CameraDesc& c = scene.cameras[f];
    if (c.width == first.width && c.height == first.height) continue;
    LOG_WARNING("render", "camera %zu is %dx%d where camera %zu is %dx%d: an image sequence "
                "usually keeps one size (a video made of these frames scales the odd ones)", f,
                c.width, c.height, range.begin, first.width, first.height);
    return;
  }
}

void WarnIfCheckpointsKeepLittle(const RenderArgs& args, const render::Scene& scene) {
  const uint32_t spp = static_cast<uint32_t>(scene.integrator.spp);
  if (!(args.checkpoint_s > 0) || spp <= 1) return;
  const bool passes = args.pass_spp < spp;  // 0: doubling passes
  // Tiles in sweeps matter only where a smaller tile (4 pixels a side or more) would not need them.
  const int side = WholeTileSide(spp);
  const bool sweeps = side > 0 && args.tile_size > side;
  if (!passes && !sweeps) return;
  LOG_WARNING("render", "--checkpoint-s: a pixel is kept by --resume once it has all its %u "
              "samples, and %s, so checkpoints (and an interrupted run) keep little or nothing "
              "until the frame's end; %s", spp,
              passes ? "progressive passes give it the last of them in the last pass"
                     : "a tile this large takes them in several sweeps",
              WholeTilesAdvice(spp).c_str());
}

void EndIfInterruptedBetweenFrames(size_t frame, FrameRange range, FrameWriter* writer,
                                   const AfterInterrupt& then) {
  const int signal = InterruptSignal();
  if (signal == 0) return;
  const Status s = writer->Finish();
  const char* name = InterruptName(signal);
  const std::string said =
      frame == range.begin
          ? StrFormat("interrupted (%s) before the first frame", name)
          : StrFormat("interrupted (%s) as frame %zu ended: %s; %s not rendered", name, frame - 1,
                      s.ok() ? "it is written" : s.message().c_str(),
                      frame + 1 == range.end ? StrFormat("frame %zu is", frame).c_str()
                                             : StrFormat("frames %zu to %zu are", frame,
                                                         range.end - 1).c_str());
  std::fprintf(stderr, "raystack render: %s\n", said.c_str());
  if (*InterruptCause(signal)) std::fprintf(stderr, "raystack render: %s\n", InterruptCause(signal));
  std::fflush(nullptr);
  then(said);
  std::fflush(nullptr);
  std::_Exit(128 + signal);
}

namespace {

// What a frame that stops early (interrupted, failed) leaves at `path` (and `png`, its
// quick-look with --png), for its message; `resume` says when --resume is worth it ("the same
// command", or after a fix).
std::string WhatIsKept(const Checkpoints::Kept& kept, const render::Film& film,
                       const std::string& path, const std::string& png, uint32_t spp,
                       const char* resume) {
  const std::string written = png.empty() ? path : path + " (and " + png + ")";
  if (kept.finished > 0)
    return StrFormat("the frame so far is in %s, %llu of %llu pixels with all their samples; %s "
                     "with --resume keeps those and renders the rest", written.c_str(),
                     static_cast<unsigned long long>(kept.finished),
                     static_cast<unsigned long long>(film.width()) *
                         static_cast<unsigned long long>(film.height()),
                     resume);
  const std::string next = StrFormat("next time, %s; or --time-limit, which ends the frame with "
                                     "the samples it has", WholeTilesAdvice(spp).c_str());
  if (kept.written)
    return StrFormat("the frame so far is in %s to look at, but no pixel has all its %u samples "
                     "yet (each pass covers every pixel a little), so --resume keeps none of it "
                     "(%s)", written.c_str(), spp, next.c_str());
  std::error_code ec;
  const std::string there = std::filesystem::exists(path, ec) ? path + " is left as it was"
                                                              : "no image is written to " + path;
  if (film.samples_merged() == 0) return "no sample is merged yet: " + there;
  return StrFormat("no pixel has all its %u samples yet, so nothing is kept for --resume, and %s "
                   "(%s)", spp, there.c_str(), next.c_str());
}

}  // namespace

void EndInterrupted(int signal, Checkpoints* checkpoints, const render::Film& film,
                    const std::string& path, uint32_t spp, const AfterInterrupt& then,
                    const std::string& sigterm_hint) {
  const char* name = InterruptName(signal);
  Expected<Checkpoints::Kept> kept = checkpoints->Final(film, spp);
  const std::string said =
      kept.ok() ? StrFormat("interrupted (%s): %s", name,
                            WhatIsKept(*kept, film, path, checkpoints->png(), spp, "the same command").c_str())
                : StrFormat("interrupted (%s); not written: %s", name,
                            kept.status().message().c_str());
  std::fprintf(stderr, "raystack render: %s\n", said.c_str());
  if (signal == SIGTERM && !sigterm_hint.empty())
    std::fprintf(stderr, "raystack render: %s\n", sigterm_hint.c_str());
  if (*InterruptCause(signal)) std::fprintf(stderr, "raystack render: %s\n", InterruptCause(signal));
  std::fflush(nullptr);
  then(said);
  std::fflush(nullptr);
  std::_Exit(128 + signal);
}

Status KeepFrameSoFar(const Status& why, Checkpoints* checkpoints, const render::Film& film,
                      const std::string& path, uint32_t spp) {
  if (film.samples_merged() == 0) return why;
  Expected<Checkpoints::Kept> kept = checkpoints->Final(film, spp);
  if (!kept.ok())
    return Status::Error(why.message() + "; the frame so far could not be written either: " +
                         kept.status().message());
  return Status::Error(why.message() + "; " +
                       WhatIsKept(*kept, film, path, checkpoints->png(), spp,
                                  "once the cause is fixed, the same command"));
}

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

Status ResumeInto(const RenderArgs& args, const render::Scene& scene, size_t f,
                  render::FramePlan* plan, render::Film* film) {
  if (!args.resume) return OkStatus();
  const std::string exr = FrameExrPath(args, scene, f);
  Expected<ResumePlan> resume =
      PlanResume(exr, plan->width, plan->height, plan->spp(), Provenance(scene, f));
  if (!resume.ok()) return resume.status();
  // A checkpoint is continued only from the store it was rendered from, which the provenance
  // tells by the index's checksum. A master that cannot read the index (under mpirun only the
  // slaves need the store) cannot tell: it took a checkpoint of another model at the same path
  // and finished it, a mixed image marked complete. (Without a checkpoint there is nothing to
  // tell: a requeued job that always passes --resume starts.)
  if (!resume->finished.empty() && !StoreChecksum(scene.store))
    return Status::Error(StrFormat("--resume: cannot read %s/%s here, so %s's store cannot be "
                                   "told from this one; run the master where the store is "
                                   "readable", scene.store.c_str(), store::kIndexFile, exr.c_str()));
  const size_t tiles = DropFinishedTiles(*resume, plan);
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

}  // namespace raystack::master
