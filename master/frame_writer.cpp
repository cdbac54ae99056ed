#include "master/frame_writer.h"

#include <sys/resource.h>
#include <unistd.h>

#include <cstdio>

#include "common/base/thread_name.h"
#include "common/image/exr_io.h"
#include "common/image/png_writer.h"

namespace raystack::master {

FrameWriter::FrameWriter(bool announce) : announce_(announce) {
  // From here, not from the writer's thread, which drops to nice 19 for background images:
  // the last frame's all-core compression runs at the job's priority.
  image::StartExrThreads();
  thread_ = std::thread([this] {
    SetThreadName("rs-write");
    Loop();
  });
}

FrameWriter::~FrameWriter() {
  {
    std::lock_guard lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  thread_.join();
}

Status FrameWriter::Write(Image image) {
  std::unique_lock lock(mu_);
  cv_.wait(lock, [&] { return !queued_; });
  if (!error_.ok()) return error_;
  queued_ = std::move(image);
  cv_.notify_all();
  return OkStatus();
}

bool FrameWriter::HasRoom() {
  std::lock_guard lock(mu_);
  return !queued_;
}

Status FrameWriter::Finish() {
  std::unique_lock lock(mu_);
  cv_.wait(lock, [&] { return !queued_ && !writing_; });
  return error_;
}

void FrameWriter::Loop() {
  std::unique_lock lock(mu_);
  for (;;) {
    cv_.wait(lock, [&] { return queued_ || stop_; });
    if (!queued_) return;  // stopped with nothing left to write
    Image image = std::move(*queued_);
    queued_.reset();
    writing_ = true;
    cv_.notify_all();  // a Write waiting for room may queue the next one
    lock.unlock();
    // Linux applies a thread id's priority to that thread alone. Unprivileged, the priority
    // cannot be raised back, hence "for good"; a refusal only leaves it where it was.
    if (image.background) (void)setpriority(PRIO_PROCESS, static_cast<id_t>(gettid()), 19);
    Status s = image::WriteExr(image.exr, image.layers,
                               image.background ? image::ExrThreads::kCallingThread
                                                : image::ExrThreads::kAllCores);
    if (s.ok() && !image.png.empty()) s = image::WritePng(image.png, image.layers, image.exposure);
    if (image.done) image.done(s);
    else if (s.ok() && announce_) std::printf("  wrote %s\n", image.exr.c_str());
    lock.lock();
    writing_ = false;
    if (error_.ok() && !image.done) error_ = s;
    cv_.notify_all();
  }
}

}  // namespace raystack::master
