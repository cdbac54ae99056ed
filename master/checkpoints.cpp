#include "master/checkpoints.h"

#include <chrono>
#include <csignal>
#include <filesystem>

#include "common/base/log.h"
#include "common/image/exr_io.h"

namespace raystack::master {
namespace {

uint64_t FinishedPixels(const image::ImageLayers& layers, uint32_t spp) {
  uint64_t finished = 0;
  for (const uint32_t n : layers.samples) finished += n >= spp;
  return finished;
}

}  // namespace

Checkpoints::Checkpoints(double every_s, std::string path, std::string provenance,
                         FrameWriter* writer, int64_t kill_after, int64_t fail_first)
    : every_s_(every_s), path_(std::move(path)), provenance_(std::move(provenance)),
      writer_(writer), fail_first_(fail_first),
      written_(std::make_shared<Written>(Written{kill_after})) {}

bool Checkpoints::KeepsWhatIsThere(uint64_t finished) const {
  std::error_code ec;
  return finished == 0 && std::filesystem::exists(path_, ec) && !image::IsPartialFrame(path_);
}

void Checkpoints::Maybe(const render::Film& film, uint32_t spp) {
  if (every_s_ <= 0) return;
  const auto now = std::chrono::steady_clock::now();
  if (std::chrono::duration<double>(now - last_).count() < every_s_) return;
  if (!writer_->HasRoom()) return;  // the writer is behind: at the next call
  last_ = now;
  if (attempts_++ < fail_first_) {  // tried again at the next interval
    LOG_WARNING("render", "checkpoint: %s: cannot write (--fault-fail-checkpoints)", path_.c_str());
    return;
  }
  FrameWriter::Image image;
  image.exr = path_;
  image.png = png_;
  image.exposure = exposure_;
  image.background = true;  // the frame goes on rendering
  image.layers = writer_->TakeSpare();  // the last image's memory, when there is one
  film.ResolveInto(&image.layers);
  if (KeepsWhatIsThere(FinishedPixels(image.layers, spp))) return;
  image.layers.provenance = provenance_;
  image.layers.partial = true;
  image.layers.stopped.clear();  // (the layers may be a stopped frame's, reused)
  image.done = [written = written_](const Status& s) {
    if (!s.ok()) {  // tried again at the next interval
      LOG_WARNING("render", "checkpoint: %s", s.message().c_str());
      return;
    }
    if (++written->count == written->kill_after) {
      LOG_WARNING("render", "killing the job after checkpoint %lld (--fault-kill-after-checkpoints)",
                  static_cast<long long>(written->count));
      std::raise(SIGKILL);
    }
  };
  // Not refused: only a failed frame image sets the writer's error, and that ends the job.
  (void)writer_->Write(std::move(image));
}

Expected<Checkpoints::Kept> Checkpoints::Final(const render::Film& film, uint32_t spp) {
  if (Status earlier = writer_->Finish(); !earlier.ok())
    return Status::Error("an earlier frame's image was not written: " + earlier.message());
  auto result = std::make_shared<Status>();
  FrameWriter::Image image;
  image.exr = path_;
  image.png = png_;
  image.exposure = exposure_;
  image.layers = writer_->TakeSpare();
  film.ResolveInto(&image.layers);
  image.layers.provenance = provenance_;
  image.layers.partial = true;
  image.layers.stopped.clear();  // (the layers may be a stopped frame's, reused)
  Kept kept;
  kept.finished = FinishedPixels(image.layers, spp);
  if (kept.finished == 0 && (film.samples_merged() == 0 || KeepsWhatIsThere(0))) return kept;
  image.done = [result](const Status& s) { *result = s; };
  RAYSTACK_RETURN_IF_ERROR(writer_->Write(std::move(image)));
  RAYSTACK_RETURN_IF_ERROR(writer_->Finish());
  RAYSTACK_RETURN_IF_ERROR(*result);
  kept.written = true;
  return kept;
}

}  // namespace raystack::master
