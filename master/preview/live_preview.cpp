#include "master/preview/live_preview.h"

#include <cstdio>

#include "common/base/log.h"
#include "master/preview/preview_frame.h"

namespace raystack::master::preview {

Expected<LivePreview> LivePreview::Start(const LivePreviewOptions& options) {
  LivePreview preview;
  if (!options.enabled) return preview;
  Expected<std::unique_ptr<PreviewServer>> server = PreviewServer::Start(options.server);
  if (!server.ok()) return server.status();
  preview.server_ = std::move(*server);
  preview.hold_seconds_ = options.hold_seconds;
  // Always printed (also with --quiet): without it nobody can open the page.
  std::printf("preview: %s\n", preview.server_->Url().c_str());
  if (!preview.server_->token().empty())
    std::printf("preview: bound to %s, so the token above is required (token=%s)\n",
                options.server.bind.c_str(), preview.server_->token().c_str());
  else
    // The tunnel's far end is the address bound (ssh takes an IPv6 one in brackets).
    std::printf("preview: loopback only; from another machine: ssh -L %u:%s:%u THIS_HOST, "
                "then open http://localhost:%u/\n", preview.server_->port(),
                preview.server_->address().c_str(), preview.server_->port(), preview.server_->port());
  std::fflush(stdout);
  return preview;
}

void LivePreview::BeginFrame(const render::Film* film, uint32_t frame, uint32_t frames, int spp,
                             uint64_t samples_restored, uint32_t last_frame) {
  if (!server_) return;
  film_ = film;
  status_ = PreviewStatus{};
  status_.frame = frame;
  status_.frames = frames;
  status_.last_frame = last_frame == UINT32_MAX ? frames - 1 : last_frame;
  status_.spp = spp;
  status_.samples_total = static_cast<uint64_t>(film->width()) * static_cast<uint64_t>(film->height()) *
                          static_cast<uint64_t>(spp);
  // Not the film's restored samples: a finished pixel in a tile rendered again counted twice,
  // and the progress reached 100% with tiles still to render.
  status_.samples_restored = samples_restored;
  if (!Streamed(film->width(), film->height()))
    // The server warns at the terminal; the page has no image to show, so it says why.
    status_.note = StrFormat("a %dx%d frame is larger than the preview streams (4096 x 4096 "
                             "pixels): only its progress is shown here", film->width(), film->height());
  start_ = std::chrono::steady_clock::now();
  server_->AttachFilm(film, frame);
  server_->Publish(status_);
}

void LivePreview::Update(const std::function<std::vector<RankTiles>()>& tiles) {
  if (!server_ || film_ == nullptr) return;
  status_.samples_done = film_->samples_merged();
  status_.elapsed_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  // Every pixel batch carries the rays its thread traced since its last one, so the film's
  // count is live (a batch behind per thread); unknown until the first batch.
  const uint64_t rays = film_->rays_traced();
  if (rays > 0 && status_.elapsed_seconds > 0)
    status_.rays_per_second = static_cast<double>(rays) / status_.elapsed_seconds;
  status_.tiles = tiles();
  server_->Publish(status_);
}

void LivePreview::EndFrame(double rays_per_second) {
  if (!server_ || film_ == nullptr) return;
  status_.samples_done = film_->samples_merged();
  status_.elapsed_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  status_.rays_per_second = rays_per_second;
  status_.finished = true;
  status_.tiles.clear();
  server_->DetachFilm();  // the final copy first, so the status never runs ahead of the image
  server_->Publish(status_);
  film_ = nullptr;
}

void LivePreview::KeepImageSoFar() {
  if (film_ == nullptr) return;
  status_.samples_done = film_->samples_merged();
  status_.elapsed_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  server_->DetachFilm();  // the image so far stays up
  film_ = nullptr;
}

void LivePreview::Fail(const Status& why) {
  if (!server_) return;
  KeepImageSoFar();
  status_.finished = false;  // a write may fail after the frame ended
  status_.failed = true;
  status_.note = "failed: " + why.message();
  status_.tiles.clear();
  server_->Publish(status_);
  // Said now: the error the job ends with is printed after the hold.
  if (hold_seconds_ > 0) std::fprintf(stderr, "raystack render: %s\n", status_.note.c_str());
  Finish();
}

void LivePreview::Interrupted(const std::string& said) {
  if (!server_) return;
  KeepImageSoFar();
  status_.finished = false;  // between frames: the last one ended, the job did not
  status_.interrupted = true;
  status_.note = said;
  status_.tiles.clear();
  server_->Publish(status_);
  server_->Drain(kLastWordSeconds);
  server_->Stop();
}

void LivePreview::Finish() {
  if (!server_) return;
  if (hold_seconds_ > 0) {
    std::printf("preview: showing the last image for %g s more (Ctrl-C ends it)\n", hold_seconds_);
    std::fflush(stdout);
    server_->Hold(hold_seconds_);
  } else {
    server_->Drain(kLastWordSeconds);  // closed at once, the page could miss the final image
  }
  server_->Stop();
  const ServerCounters c = server_->counters();
  std::printf("preview: %llu frames sent to viewers, %llu skipped for slow viewers, %llu requests "
              "refused", static_cast<unsigned long long>(c.frames_sent),
              static_cast<unsigned long long>(c.frames_skipped), static_cast<unsigned long long>(c.refused));
  if (c.evicted > 0)
    std::printf(", %llu idle connections closed to make room", static_cast<unsigned long long>(c.evicted));
  std::printf("\n");
}

}  // namespace raystack::master::preview
