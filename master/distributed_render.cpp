#include "master/distributed_render.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "common/base/build_id.h"
#include "common/base/byte_sizes.h"
#include "common/base/interrupt.h"
#include "common/base/log.h"
#include "common/base/process_names.h"
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
#include "master/master_node.h"
#include "master/output_lock.h"
#include "master/preflight.h"
#include "master/preview/live_preview.h"
#include "master/provenance.h"
#include "slave/direct_reads.h"
#include "slave/peer_blocks.h"
#include "slave/render_engine.h"
#include "slave/slave_node.h"

namespace raystack::master {
namespace {

// An operator's slave was killed, and the master said only "interrupted (SIGTERM)".
constexpr const char* kMpirunSigterm =
    "(mpirun sends SIGTERM at Ctrl-C, at a scheduler's time limit, when the terminal or ssh "
    "session that started it closes (its SIGHUP), and when a rank dies: killed, or out of memory; "
    "under mpirun --enable-recovery the job goes on without a lost slave)";


// Per slave, the names a one-process run's --stats uses for the same figures
// (slave::RenderStats::ToJson), and the job's own (tiles, peers, bytes to and from the master).
// `record`: the frame's (FrameRecordJson).
std::string FiguresJson(const std::string& record, const FrameFigures& f) {
  std::string s = "{\n" + record +
                  StrFormat("  \"seconds\": %g,\n  \"imbalance\": %g,"
                            "\n  \"utilisation\": %g,\n  \"slaves\": [",
                            f.seconds, f.imbalance(), f.utilisation());
  const auto u = [](uint64_t v) { return static_cast<unsigned long long>(v); };
  for (size_t i = 0; i < f.slaves.size(); ++i) {
    const SlaveFigures& x = f.slaves[i];
    const wire::FrameDone& d = x.done;
    uint64_t rays = 0;
    for (const uint64_t r : d.rays_by_type) rays += r;
    // The host as its hello gave it (printable ASCII): quotes and backslashes escaped.
    std::string host;
    for (const char c : x.host) host += c == '"' || c == '\\' ? std::string("\\") + c : std::string(1, c);
    const std::string budget = d.cache_budget_bytes == std::numeric_limits<uint64_t>::max()
                                   ? std::string("null")  // in core
                                   : std::to_string(d.cache_budget_bytes);
    s += StrFormat(
        "%s\n    {\"rank\": %d, \"host\": \"%s\", \"dropped\": %s, \"seconds\": %g, \"engine_seconds\": %g, "
        "\"threads\": %u, \"rays\": {\"primary\": %llu, \"shadow\": %llu, \"specular\": %llu, "
        "\"diffuse\": %llu}, \"rays_total\": %llu, \"samples\": %llu, \"tiles\": %llu, "
        "\"blocks_loaded\": %llu, \"blocks_distinct\": %llu, \"bytes_read\": %llu, "
        "\"reads\": %llu, \"direct_reads\": %s, \"block_visits\": %llu, "
        "\"cache_hit_rate\": %g, \"loader_busy_seconds\": %g, \"ray_idle_seconds\": %g, "
        "\"ray_tile_wait_seconds\": %g, \"ray_busy_seconds\": %g, \"ray_cpu_seconds\": %g, "
        "\"loader_cpu_seconds\": %g, \"process_cpu_seconds\": %g, \"cache_budget_bytes\": %s, "
        "\"cache_peak_bytes\": %llu, \"evictions\": %llu, \"peak_stack_bytes\": %llu, "
        "\"peak_stack_rays\": %llu, \"peak_rss_bytes\": %llu, \"bytes_from_peers\": %llu, "
        "\"bytes_to_peers\": %llu, \"fetches\": %llu, \"fetch_wait_seconds\": %g, "
        "\"fetch_runs\": %llu, \"bytes_to_master\": %llu, \"pixel_bytes\": %llu, "
        "\"bytes_from_master\": %llu}",
        i ? "," : "", x.rank, host.c_str(), x.dropped ? "true" : "false", d.seconds, d.engine_seconds,
        d.ray_threads, u(d.rays_by_type[0]), u(d.rays_by_type[1]), u(d.rays_by_type[2]),
        u(d.rays_by_type[3]), u(rays), u(d.samples), u(d.tiles), u(d.blocks_loaded),
        u(d.blocks_distinct), u(d.bytes_read), u(d.reads),
        d.flags & wire::kFrameDoneDirectReads ? "true" : "false", u(d.block_visits),
        d.cache_hit_rate, d.loader_busy_seconds, d.block_wait_seconds, d.tile_wait_seconds,
        d.busy_seconds, d.ray_cpu_seconds, d.loader_cpu_seconds, d.process_cpu_seconds,
        budget.c_str(), u(d.cache_peak_bytes), u(d.evictions), u(d.peak_stack_bytes),
        u(d.peak_stack_rays), u(d.peak_rss_bytes), u(d.bytes_from_peers), u(d.bytes_to_peers),
        u(d.fetches), d.fetch_wait_seconds, u(d.fetch_runs), u(x.bytes_received),
        u(x.pixel_bytes), u(x.bytes_sent));
  }
  return s + "\n  ]\n}";
}

// `remote_blocks`: whether the slaves read blocks from peers, where the master can tell.
Status RunMaster(const RenderArgs& args, const render::Scene& scene, transport::Transport* net,
                 ConvergenceLog* log, bool coarse_rounds, std::optional<bool> remote_blocks) {
  const std::string output = OutputOf(args, scene);
  const size_t frames = scene.cameras.size();
  const FrameRange range = FramesOf(args, scene);
  MasterOptions options;
  options.lost_after = std::chrono::milliseconds(static_cast<int64_t>(args.lost_after_s * 1000));
  options.beat = true;
  options.identity = JobIdentity{BuildId(), StoreChecksumAtStart(scene.store), SceneChecksum(scene),
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
    const std::vector<std::string> dropped = master.SlavesDropped();
    for (size_t i = 0; i < by_slave.size(); ++i)
      ranks.push_back({static_cast<int>(i) + 1, std::move(by_slave[i]),
                       i < dropped.size() ? dropped[i] : std::string()});
    return ranks;
  };
  const InterruptsHeld held;  // to the last write (declared before `writer`: outlives it)
  StatsFile stats_file(args.stats);  // (before the writer, whose thread appends to it)
  FrameWriter writer(!args.quiet, args.fail_writes, FrameWriter::kRetrySeconds, args.slow_writes_s);
  std::unique_ptr<render::Film> reused_film;  // FilmFor
  std::unique_ptr<image::ImageLayers> reference;  // LoadReference
  SequenceProgress sequence(range, args.quiet);
  for (size_t f = range.begin; f < range.end; ++f) {
    WarnIfStoreReplaced(scene.store);
    const render::Camera camera(scene.cameras[f]);
    const std::string exr_path = FrameExrPath(args, scene, f);  // its image, checkpoints too
    render::Film& film = FilmFor(camera, &reused_film);
    render::FramePlan plan = PlanOf(args, scene, camera, coarse_rounds);
    Status status = ResumeInto(args, scene, f, &plan, &film);
    const uint64_t total = plan.samples_to_render();  // less what --resume kept
    if (status.ok()) status = LoadReference(args, f, frames, camera, &reference);
    if (!status.ok()) {
      master.Shutdown(1);
      preview->Fail(status);  // the page says why, for the hold time
      return status;
    }
    ConvergenceMonitor monitor(film, plan, args.stop, static_cast<uint32_t>(f), log,
                               reference.get(), args.log_interval_s);
    FrameFigures figures;
    // The page first: once the slaves are told, mpirun may end this process at any moment.
    const AfterInterrupt interrupted = [&](const std::string& said) {
      preview->Interrupted(said);
      (void)stats_file.Finish();  // a stream's array closed: the process ends with _Exit
      master.Abandon();
    };
    EndIfInterruptedBetweenFrames(f, range, &writer, interrupted);
    {
      ProgressReporter progress(FrameTitle(f, frames), total, "samples",
                                args.quiet);
      uint64_t shown = 0;
      Checkpoints checkpoints(args.checkpoint_s, exr_path,
                              Provenance(scene, f), &writer, args.kill_after_checkpoints,
                              args.fail_checkpoints);
      checkpoints.AlsoPng(FramePngPath(args, scene, f), args.exposure);
      preview->BeginFrame(&film, static_cast<uint32_t>(f), static_cast<uint32_t>(frames),
                          scene.integrator.spp, plan.total_samples() - total,
                          static_cast<uint32_t>(range.end - 1));
      status = master.RunFrame(static_cast<uint32_t>(f), plan, &film, [&] {
                                 if (const int signal = InterruptSignal())
                                   EndInterrupted(signal, &checkpoints, film,
                                                  exr_path, plan.spp(),
                                                  interrupted, kMpirunSigterm);
                                 const uint64_t done = film.samples_merged();
                                 progress.Update(done - shown);
                                 shown = done;
                                 checkpoints.Maybe(film, plan.spp());
                                 const bool go_on = monitor.Poll();
                                 preview->SetErrorEstimate(monitor.last().error_estimate);
                                 preview->Update(assigned);
                                 return go_on;
                               },
                               &figures);
      if (!status.ok()) {
        progress.Abandon();
        status = KeepFrameSoFar(status, &checkpoints, film, exr_path,
                                plan.spp());
      }
    }
    image::ImageLayers resolved = writer.TakeSpare();
    if (status.ok()) {
      film.ResolveInto(&resolved);
      monitor.Finish(resolved);
      preview->SetErrorEstimate(monitor.last().error_estimate);  // the last pass's
      ReportStop(args, monitor);
      if (monitor.stopped()) preview->SetNote("stopped: " + monitor.stop_reason());
      uint64_t rays = 0;
      for (const SlaveFigures& s : figures.slaves) rays += s.done.rays;
      preview->EndFrame(figures.seconds > 0 ? static_cast<double>(rays) / figures.seconds
                                            : std::numeric_limits<double>::quiet_NaN());
    }
    // The frame's record goes into --stats once its image is written.
    std::string record = FiguresJson(
        FrameRecordJson(f, exr_path, camera.width(), camera.height(), plan.spp(),
                        monitor.stopped() ? monitor.stop_reason() : "", plan.total_samples() - total),
        figures);
    Expected<std::string> exr =
        status.ok() ? WriteFrame(args, scene, f, film, std::move(resolved),
                                   monitor.stopped() ? monitor.stop_reason() : std::string(), total,
                                   &writer, [&stats_file, record = std::move(record)] { stats_file.Append(record); })
                    : Expected<std::string>(status);
    if (!exr.ok()) {  // every rank ends, none is left waiting
      master.Shutdown(1);
      preview->Fail(exr.status());  // then the page says why, for the hold time
      return exr.status();
    }
    if (!args.quiet) {
      std::printf("frame %zu: %d slaves, %.3f s, imbalance %.3f, utilisation %.3f\n", f,
                  net->size() - 1, figures.seconds, figures.imbalance(), figures.utilisation());
      for (const SlaveFigures& s : figures.slaves) {
        const std::string on = s.host.empty() ? std::string() : " (on " + s.host + ")";
        if (s.dropped) {
          std::printf("  rank %d%s: dropped (%s)\n", s.rank, on.c_str(), s.failure.c_str());
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
        // The cache and the process's peak, as a one-process run prints them (an operator
        // sizing --cache-mb reads them here).
        const std::string cache =
            s.done.cache_budget_bytes == std::numeric_limits<uint64_t>::max()
                ? StrFormat("; cache: in core, peak RSS %.1f MB",
                            static_cast<double>(s.done.peak_rss_bytes) / 1e6)
                : StrFormat("; cache: hit rate %.4f, peak %s of %s, %llu evictions; "
                            "peak RSS %.1f MB", s.done.cache_hit_rate,
                            MiB(s.done.cache_peak_bytes).c_str(),
                            MiB(s.done.cache_budget_bytes).c_str(),
                            static_cast<unsigned long long>(s.done.evictions),
                            static_cast<double>(s.done.peak_rss_bytes) / 1e6);
        std::printf("  rank %d%s: %.3f s (ray threads busy %.3f s; CPU: process %.3f s, ray threads "
                    "%.3f s, loader %.3f s), %llu rays, %llu tiles, %llu "
                    "blocks loaded (%llu distinct), %.1f MB of blocks (%s reads)%s, %.1f MB sent "
                    "to the master%s\n",
                    s.rank, on.c_str(), s.done.seconds, s.done.busy_seconds, s.done.process_cpu_seconds,
                    s.done.ray_cpu_seconds, s.done.loader_cpu_seconds,
                    static_cast<unsigned long long>(s.done.rays),
                    static_cast<unsigned long long>(s.done.tiles),
                    static_cast<unsigned long long>(s.done.blocks_loaded),
                    static_cast<unsigned long long>(s.done.blocks_distinct),
                    static_cast<double>(s.done.bytes_read) / 1e6,
                    s.done.flags & wire::kFrameDoneDirectReads ? "direct" : "buffered", peers.c_str(),
                    static_cast<double>(s.bytes_received) / 1e6, cache.c_str());
      }
    }
    sequence.FrameDone(f, total > 0);
  }
  if (const Status written = writer.Finish(); !written.ok()) {  // the last frame's write
    master.Shutdown(1);
    preview->Fail(written);
    return written;
  }
  if (!master.Shutdown(0)) LOG_WARNING("master", "a slave did not acknowledge the end of the job");
  if (Status s = stats_file.Finish(); !s.ok()) {
    preview->Fail(s);
    return s;
  }
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
  *why = StrFormat("store %s on disk, %s per slave's share, %s cache per slave",
                   MiB(stored).c_str(), MiB(share).c_str(), MiB(args.engine.cache_bytes).c_str());
  if (args.blocks == "rem") return true;
  if (args.blocks == "loc") return false;
  return fits;
}

// The slaves on this slave's machine (itself included): every rank there but the master.
int SlavesHere(const transport::Transport& net) {
  const transport::Transport::HostShare here = net.host_share();
  return std::max(1, here.ranks - (here.with_rank0 ? 1 : 0));
}

Status RunSlave(const RenderArgs& args, const render::Scene& scene, transport::Transport* net) {
  Expected<std::unique_ptr<store::StoreReader>> store = OpenSceneStore(scene);
  if (store.ok()) (void)StoreChecksumAtStart(scene.store);  // the store this slave renders
  if (store.ok()) {  // before any block is read (PeerBlocks reads this slave's share)
    // Each slave decides for its own machine; the master prints each one's reads per frame.
    std::string reads;
    Status s = slave::ChooseReads(args.direct_io, args.engine.cache_bytes, store->get(), &reads);
    if (s.ok()) s = CheckSlaveMemory(EngineMemoryOf(args.engine, **store), SlavesHere(*net), HostName());
    if (!s.ok()) store = s;
  }
  if (!args.threads_given) WarnOfIdleCores(SlavesHere(*net));
  std::unique_ptr<slave::PeerBlocks> peers;
  slave::EngineOptions options = args.engine;
  const bool faulty = args.fault_rank == 0 || args.fault_rank == net->rank();
  if (faulty) options.faults.fail_read = args.fail_read;
  std::string why;
  if (store.ok() && UseRemoteBlocks(args, **store, net->size() - 1, &why)) {
    peers = std::make_unique<slave::PeerBlocks>(net, **store, options.faults);
    // The share this slave keeps for its peers counts against its budget.
    if (peers->owned_bytes() >= options.cache_bytes)
      store = Status::Error(StrFormat("--blocks rem: this slave's share of the store (%s) "
                                      "does not fit its --cache-mb (%s); use --blocks loc "
                                      "or more slaves", MiB(peers->owned_bytes()).c_str(),
                                      MiB(options.cache_bytes).c_str()));
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
  hello.store_checksum = StoreChecksumAtStart(scene.store).value_or(0);
  hello.scene_checksum = SceneChecksum(scene);
  wire::SetHelloText(hello.build, BuildId());
  wire::SetHelloText(hello.host, HostName());
  if (Status s = net->Send(0, wire::Encode(static_cast<uint32_t>(net->rank()), hello)); !s.ok())
    return s;
  const render::MaterialTable materials =
      render::MaterialTable::Build((*store)->materials(), scene, net->rank() == 1);
  if (net->rank() == 1) WarnIfUnlit(scene, materials, **store);  // once for the job
  slave::NodeFaults faults;
  if (faulty) faults = {args.kill_after_tiles, args.stall_after_tiles, args.stall_s};
  slave::SlaveNode node(net, engine->get(), peers.get(), faults, MasterLostAfter(args));
  const FrameRange range = FramesOf(args, scene);
  for (size_t f = range.begin; f < range.end; ++f) {
    const render::Camera camera(scene.cameras[f]);
    slave::RenderStats stats;
    render::Scene copy;
    const Status s = node.RunFrame(static_cast<uint32_t>(f), render::SceneOfFrame(scene, f, &copy),
                                   materials, camera, &stats);
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

}  // namespace

Status RenderDistributed(const RenderArgs& args, transport::Transport* net) {
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
    Status s = CheckMemory(*scene, 0);
    if (s.ok()) s = CheckOutputOf(args, *scene);
    // (After the outputs' checks: opening empties the log. Locked, held to the end.)
    Expected<std::unique_ptr<ConvergenceLog>> log =
        s.ok() ? OpenLog(args) : Expected<std::unique_ptr<ConvergenceLog>>(s);
    if (!log.ok()) s = log.status();
    if (s.ok()) WarnIfCheckpointsKeepLittle(args, *scene);
    if (s.ok()) WarnIfFrameSizesDiffer(*scene, FramesOf(args, *scene));
    Expected<OutputLock> output_lock =  // held to the end of the job
        s.ok() ? OutputLock::Take(FrameExrPath(args, *scene, 0), FramesOf(args, *scene).begin,
                                  FramesOf(args, *scene).end)
               : Expected<OutputLock>(s);
    if (!output_lock.ok()) s = output_lock.status();
    Expected<std::optional<OutputLock>> stats_lock =  // held to the end of the job too
        s.ok() ? LockStats(args) : Expected<std::optional<OutputLock>>(s);
    if (!stats_lock.ok()) s = stats_lock.status();
    if (s.ok()) s = CheckNoUnfinishedFrame(args, *scene);
    if (s.ok()) s = CheckReferences(*scene, args.reference, FramesOf(args, *scene));
    if (!s.ok()) {  // before the slaves start a frame
      MasterNode(net).Shutdown(1);
      return s;
    }
    // The master reads the store's index when it can (it need not: the slaves read the store),
    // to log the slaves' block mode and to plan the first pass.
    Expected<std::unique_ptr<store::StoreReader>> store = OpenSceneStore(*scene);
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
            "--blocks rem: a slave's share of the store (%s on average over %d slaves) "
            "does not fit its --cache-mb (%s); use --blocks loc, more slaves or a larger "
            "--cache-mb", MiB(share).c_str(), net->size() - 1, MiB(args.engine.cache_bytes).c_str()));
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
    Status done = RunMaster(args, *scene, net, log->get(), coarse_rounds,
                            store.ok() ? std::optional<bool>(rem) : std::nullopt);
    if (done.ok() && *log) done = (*log)->Close();  // rows lost: said after the images
    return done;
  }
  return RunSlave(args, *scene, net);
}

}  // namespace raystack::master
