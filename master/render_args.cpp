#include "master/render_args.h"

#include <algorithm>
#include <filesystem>
#include <thread>

#include "common/base/log.h"
#include "common/base/option_number.h"
#include "common/base/unknown_option.h"
#include "common/base/usable_cores.h"
#include "slave/block_loader.h"

namespace raystack::master {

const char* const kRenderUsage = R"(usage: raystack render SCENE.json [options]

Renders a block store (made by raystack-prep) as the scene file describes (format:
SCENE_FORMAT.md, in the source's common/render/ or in @DOCS@) and writes an
OpenEXR image with layers R G B A, Z, N, albedo, samples and variance, plus a tone-mapped PNG
beside it. Blocks are loaded on demand into a cache of --cache-mb; rays that need a missing
block wait in that block's queue while a loader thread reads it (the ray stack), so the store
may be far larger than the cache.

options:
  --mode stack|sync|incore|bvh
                            stack: the ray stack (default); sync: a miss blocks the thread
                            while its block is read (the baseline); incore: load every block
                            first, no budget; bvh: load every block, then trace through one
                            BVH over all triangles (the fastest per ray when the model fits
                            in RAM, after a build of ~1 s per million triangles: worth it for
                            many samples or frames; about twice incore's memory; same image)
  --cache-mb N              block cache budget in MiB, never exceeded (default 512)
  --threads N               ray threads (default: the cores this process may use, at most 64)
  --feed-fraction P         start the next tile once this fraction of the current one is
                            done (default 0.1)
  --tile-size N             tile side in pixels (default 32)
  --tile-ahead P            under mpirun, a slave thread asks for its next two tiles once
                            this fraction of its current one is done (default 0: at once)
  --batch N                 samples per pixel batch a slave sends (default 1024)
  --checkpoint-s S          write the EXR every S seconds while rendering (default 0: only
                            at the end), on a thread of its own at low priority while the
                            render goes on, atomically (a temporary file, then a rename); a
                            failed checkpoint is logged and tried again, never fatal; a
                            pixel is kept once it has all its samples, so with progressive
                            passes little is kept before the last pass: --pass-spp SPP with
                            a --tile-size T where T*T*SPP <= 16384 keeps tiles as they end
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
                            --reference (format: README.md, "Error against run time")
  --log-interval S          seconds between convergence-log rows (default 0.5)
  --reference REF.exr       an image to measure the convergence log's RMSE and relMSE against
                            (same size; with several cameras named as the outputs are:
                            REF-0.exr, REF-1.exr, ..., REF-00.exr ... with 11 or more)
  --frames A-B              render only cameras A to B of the scene's list (A, A-B or A-: to
                            the last), counted from 0; their files keep their numbers
  --output FILE.exr         override the scene's output path (the PNG goes beside it;
                            several cameras: FILE-0.exr, FILE-1.exr, ..., with as many
                            digits as the last frame's (FILE-07.exr of 24); a run of '#' or
                            a %04d in the name takes the frame's number instead)
  --no-png                  do not write the PNG quick-look
  --exposure EV             exposure of the PNG quick-look (default 0)
  --stats FILE              also write the run's statistics as JSON, a frame's once its image
                            is written (/dev/stdout: with -q, the JSON alone)
  --preview PORT|any        serve a live preview of the render at http://ADDR:PORT/ (any: a
                            free port; the address is printed at start); default off
  --preview-bind ADDR       the preview's address (default 127.0.0.1, this machine only; any
                            other, e.g. 0.0.0.0, requires the random token printed at start)
  --preview-hold S          keep the preview up S seconds after the render, also after a
                            failure (Ctrl-C ends it)
  --lost-after S            under mpirun, the master drops a slave it has not heard from for
                            S seconds (default 5; slaves send a heartbeat every 0.5 s); its
                            unfinished tiles go to the others, and the image stays exact.
                            Start the job with `mpirun --enable-recovery` so that a dead
                            slave does not end every rank
  -q, --quiet               no progress or information lines (warnings and errors
                            are still printed)
  -h, --help                this text
  --version                 this build's version and git commit (as `raystack --version`)

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
  --fault-fail-writes N     the first N writes of frame images fail, as on a full disk (each
                            is tried again, 1, 2, 4 ... s apart)
  --fault-slow-writes S     each write of a frame image first waits S seconds, as on a slow
                            disk (the images of finished frames queue behind the render)
)";

namespace {

// --frames: "A", "A-B" or "A-" (to the last camera).
Status ParseFrameRange(const std::string& range, size_t* first, size_t* last) {
  const size_t dash = range.find('-');
  const std::string a = range.substr(0, dash);
  const std::string b = dash == std::string::npos ? a : range.substr(dash + 1);
  const bool to_end = dash != std::string::npos && b.empty();
  if (!ParseNumber(a, first) || (!to_end && !ParseNumber(b, last)))
    return Status::Error("--frames " + range + ": give A, A-B or A- (cameras counted from 0, "
                         "e.g. --frames 10-20)");
  if (to_end) *last = SIZE_MAX;
  if (*last < *first)
    return Status::Error("--frames " + range + ": the last frame comes before the first");
  return OkStatus();
}

}  // namespace

std::string RenderUsage() {
  std::error_code ec;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  std::filesystem::path docs = "/usr/share/doc/raystack";
  if (!ec && std::filesystem::is_directory(exe.parent_path().parent_path() / "share/doc/raystack", ec))
    docs = exe.parent_path().parent_path() / "share/doc/raystack";
  std::string usage = kRenderUsage;
  usage.replace(usage.find("@DOCS@"), 6, docs.string() + "/");
  return usage;
}

void WarnOfIdleCores(int slaves_here) {
  const std::string note = RayThreadsCapNote(static_cast<unsigned>(UsableCores()),
                                             std::thread::hardware_concurrency(), slaves_here);
  if (!note.empty()) LOG_WARNING("render", "%s", note.c_str());
}

Status ParseRenderArgs(int argc, char** argv, RenderArgs* a, bool* help) {
  bool bind_given = false, hold_given = false;
  a->engine.threads = DefaultRayThreads(static_cast<unsigned>(UsableCores()));
  bool log_options_given = false, checkpoint_faults_given = false;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--blocks" || arg == "--lost-after" || arg == "--fault-rank" ||
        arg == "--fault-kill-after-tiles" || arg == "--fault-stall-after-tiles" ||
        arg == "--fault-stall-s")
      a->slave_options.push_back(arg);
    log_options_given |= arg == "--reference" || arg == "--log-interval";
    checkpoint_faults_given |=
        arg == "--fault-kill-after-checkpoints" || arg == "--fault-fail-checkpoints";
    auto value = [&](std::string* out) -> Status {
      if (i + 1 >= argc) return Status::Error(arg + " needs a value");
      *out = argv[++i];
      return OkStatus();
    };
    // `unit` names what the number counts, for the message ("MiB").
    auto number = [&](auto* out, double lo, double hi, const char* unit = "") -> Status {
      std::string v;
      RAYSTACK_RETURN_IF_ERROR(value(&v));
      return ParseOptionNumber(arg, v, out, lo, hi, unit);
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
      RAYSTACK_RETURN_IF_ERROR(number(&mb, 0.001, 1 << 24, "MiB"));
      a->engine.cache_bytes = static_cast<uint64_t>(mb * 1024 * 1024);
    } else if (arg == "--threads") {
      a->threads_given = true;
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
        return Status::Error("--coarse-rounds must be auto, on or off, got '" + a->coarse_rounds + "'");
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
    } else if (arg == "--frames") {
      std::string range;
      RAYSTACK_RETURN_IF_ERROR(value(&range));
      RAYSTACK_RETURN_IF_ERROR(ParseFrameRange(range, &a->first_frame, &a->last_frame));
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
      // Port 0 is no port to open: it used to turn the preview off without a word.
      if (v != "any" && (!ParseNumber(v, &port) || port == 0))
        return Status::Error("--preview: '" + v + "' is not a port number (1 to 65535) or 'any' "
                             "(a free port)");
      a->preview.enabled = true;
      a->preview.server.port = port;
    } else if (arg == "--preview-bind") {
      RAYSTACK_RETURN_IF_ERROR(value(&a->preview.server.bind));
      bind_given = true;
    } else if (arg == "--preview-hold") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->preview.hold_seconds, 0, 1e9));
      hold_given = true;
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
    } else if (arg == "--fault-fail-writes") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->fail_writes, 0, 1e12));
    } else if (arg == "--fault-slow-writes") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->slow_writes_s, 0.0, 3600.0));
    } else if (arg == "--fault-fail-read") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->fail_read, 0, 1e12));
    } else if (arg == "-q" || arg == "--quiet") {
      a->quiet = true;
    } else if (!arg.empty() && arg[0] == '-') {
      return Status::Error(UnknownOption(arg));
    } else if (a->scene.empty()) {
      a->scene = arg;
    } else {
      return Status::Error("one scene file only; extra argument '" + arg + "'");
    }
  }
  if (!*help && a->scene.empty()) return Status::Error("a scene file is required (see --help)");
  // Options of the preview without the preview would be taken and do nothing.
  if (!a->preview.enabled && (bind_given || hold_given))
    return Status::Error(std::string(bind_given ? "--preview-bind" : "--preview-hold") +
                         " needs the preview on: add --preview PORT (or any)");
  // So would these: the reference and the interval are the convergence log's, and the
  // checkpoint faults need checkpoints.
  if (log_options_given && a->convergence_log.empty())
    return Status::Error("--reference and --log-interval are the convergence log's: add "
                         "--convergence-log FILE");
  if (checkpoint_faults_given && !(a->checkpoint_s > 0))
    return Status::Error("--fault-kill-after-checkpoints and --fault-fail-checkpoints need "
                         "checkpoints: add --checkpoint-s S");
  a->preview.server.exposure = a->exposure;
  return OkStatus();
}

}  // namespace raystack::master
