#include "master/frame_writer.h"

#include <sys/resource.h>
#include <unistd.h>

#include <cstdio>
#include <utility>

#include "common/base/thread_name.h"
#include "common/image/exr_io.h"
#include "common/image/png_writer.h"

namespace raystack::master {

FrameWriter::FrameWriter(bool announce) : announce_(announce) {
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

image::ImageLayers FrameWriter::TakeSpare() {
  std::lock_guard lock(mu_);
  return std::exchange(spare_, image::ImageLayers{});
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
    Status s;
    auto write = [&](image::ExrThreads threads) {
      s = image::WriteExr(image.exr, image.layers, threads);
      if (s.ok() && !image.png.empty())
        s = image::WritePng(image.png, image.layers, image.exposure);
      if (image.done) image.done(s);
    };
    if (image.background) {
      // On a thread of its own at nice 19: Linux applies a nice value to one thread, and an
      // unprivileged one cannot raise it back, so this thread stays at the job's priority for
      // the last frame (whose compression threads start from it). A refused nice only leaves
      // the priority where it was.
      std::thread low([&] {
        SetThreadName("rs-write-low");
        (void)setpriority(PRIO_PROCESS, static_cast<id_t>(gettid()), 19);
        write(image::ExrThreads::kCallingThread);
      });
      low.join();
    } else {
      write(image::ExrThreads::kAllCores);
    }
    if (!image.done && s.ok() && announce_) std::printf("  wrote %s\n", image.exr.c_str());
    lock.lock();
    spare_ = std::move(image.layers);  // a frame's or a checkpoint's: the next resolve's memory
    writing_ = false;
    if (error_.ok() && !image.done) error_ = s;
    cv_.notify_all();
  }
}

}  // namespace raystack::master
