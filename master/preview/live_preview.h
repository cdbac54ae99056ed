#pragma once
// The render command's side of the live preview: starts the server when asked, tells it about
// each frame (film, progress, tiles, rays/s) and keeps the final image up at the end. Every
// call is a no-op when the preview is off, so the render loops call it unconditionally.
// Not thread-safe: one render loop drives it (the server it feeds is thread-safe).

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "common/base/status.h"
#include "common/render/film.h"
#include "master/preview/preview_server.h"
#include "master/preview/preview_status.h"

namespace raystack::master::preview {

struct LivePreviewOptions {
  bool enabled = false;
  ServerOptions server;
  double hold_seconds = 0;  // keep serving this long after the job (SIGINT/SIGTERM end it)
};

class LivePreview {
 public:
  LivePreview() = default;  // off
  // Starts the server and prints where to look (and the token) on stdout.
  static Expected<LivePreview> Start(const LivePreviewOptions& options);

  bool on() const { return server_ != nullptr; }
  PreviewServer* server() { return server_.get(); }

  // Frame `frame` of `frames` renders into `film` (alive until EndFrame) at `spp`;
  // `samples_restored` of its samples are done already and no tile renders them again (--resume:
  // FramePlan's total_samples() - samples_to_render()).
  // `last_frame`: the job's last frame (--frames), by default frames - 1.
  void BeginFrame(const render::Film* film, uint32_t frame, uint32_t frames, int spp,
                  uint64_t samples_restored, uint32_t last_frame = UINT32_MAX);
  // Publishes the progress so far (rays/s from the rays the film has been told of); `tiles`
  // is only called when the preview is on.
  void Update(const std::function<std::vector<RankTiles>()>& tiles);
  // The current error estimate of the image (from per-pixel variance), shown until replaced;
  // NaN (the default) shows as "—".
  void SetErrorEstimate(double error) { status_.error_estimate = error; }
  // What ended the frame early ("stopped: ..."), shown on the page with the frame.
  void SetNote(std::string note) { status_.note = std::move(note); }
  // The frame is complete: its final image, and its rays per second from the engines' own
  // counts (NaN if unknown).
  void EndFrame(double rays_per_second);
  // The job failed in this frame: the page says why (and shows the image so far) for the hold
  // time, as after a job that ends well, then the server closes.
  void Fail(const Status& why);
  // SIGINT or SIGTERM ends the job now (Ctrl-C; a scheduler's time limit, which leaves a second
  // at most): the page says `said` ("interrupted (SIGINT): the frame so far is in ...") with the
  // image so far, sent within kLastWordSeconds, then the server closes; no hold.
  void Interrupted(const std::string& said);
  // The job is over: serve the final image for the hold time, then close (with no hold, once
  // the viewers have it, within kLastWordSeconds).
  void Finish();

  // The longest the job's end waits for its last status and image to reach the viewers.
  static constexpr double kLastWordSeconds = 0.5;

 private:
  // Ends the frame's live view with the film's last copy (if a frame is on), for Fail and
  // Interrupted.
  void KeepImageSoFar();

  std::unique_ptr<PreviewServer> server_;
  double hold_seconds_ = 0;
  const render::Film* film_ = nullptr;
  PreviewStatus status_;
  std::chrono::steady_clock::time_point start_;
};

}  // namespace raystack::master::preview
