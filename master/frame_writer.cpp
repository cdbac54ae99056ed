#include "master/frame_writer.h"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <system_error>
#include <utility>

#include "common/base/interrupt.h"
#include "common/base/log.h"
#include "common/base/progress.h"
#include "common/base/thread_name.h"
#include "common/image/exr_io.h"
#include "common/image/png_writer.h"

namespace raystack::master {
namespace {

// What a user can do about a failed write, from the system's words in its message: "free some
// space" was the advice for a folder made read-only too.
const char* RetryAdvice(const std::string& message) {
  std::string lower = message;
  for (char& c : lower) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  const auto says = [&](const char* words) { return lower.find(words) != std::string::npos; };
  if (says("no space left") || says("disk quota")) return "free some space";
  if (says("permission denied") || says("operation not permitted") || says("read-only file system"))
    return "make the folder writable";
  if (says("no such file or directory") || says("not a directory")) return "restore the folder";
  return "fix the cause";
}

}  // namespace

FrameWriter::FrameWriter(bool announce, int64_t fail_first, double retry_seconds, double slow_s)
    : announce_(announce), fail_first_(fail_first), retry_seconds_(retry_seconds), slow_s_(slow_s) {
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

Status FrameWriter::WriteImage(const Image& image, image::ExrThreads threads) {
  const auto write = [&] {
    if (!image.done && slow_s_ > 0)
      std::this_thread::sleep_for(std::chrono::duration<double>(slow_s_));
    if (!image.done && fail_first_ > 0) {
      --fail_first_;
      return Status::Error(image.exr + ": cannot write EXR: no space left on device "
                           "(--fault-fail-writes)");
    }
    Status s = image.png_only ? OkStatus() : image::WriteExr(image.exr, image.layers, threads);
    if (s.ok() && !image.png.empty()) s = image::WritePng(image.png, image.layers, image.exposure);
    return s;
  };
  Status s = write();
  // A checkpoint is tried again at its next interval. Out of memory is not a disk's to free:
  // waiting 10 minutes for it held a job (an address-space limit) for nothing. After SIGINT or
  // SIGTERM the job is ending: "trying again" would be untrue.
  if (s.ok() || image.done || retry_seconds_ <= 0 ||
      s.message().find("out of memory") != std::string::npos || InterruptSignal() != 0)
    return s;
  const auto start = std::chrono::steady_clock::now();
  double wait_s = 1;
  ClearProgressLine();  // (a later frame's bar may be on the line)
  const std::string how_long = retry_seconds_ >= 120 ? StrFormat("%.0f minutes", retry_seconds_ / 60)
                                                     : StrFormat("%.0f s", retry_seconds_);
  std::fprintf(stderr, "raystack render: %s; trying again every few seconds for %s (%s; Ctrl-C "
               "gives up)\n", s.message().c_str(), how_long.c_str(), RetryAdvice(s.message()));
  for (;;) {
    // Slept in short steps, so that SIGINT or SIGTERM (noted, not fatal: InterruptsHeld) ends it.
    const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(wait_s);
    while (std::chrono::steady_clock::now() < until && InterruptSignal() == 0)
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    if (InterruptSignal() != 0 ||
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() > retry_seconds_)
      return Status::Error(s.message() + StrFormat(" (tried for %.0f s)", std::chrono::duration<double>(
                                                       std::chrono::steady_clock::now() - start).count()));
    s = write();
    if (s.ok()) {
      ClearProgressLine();
      std::fprintf(stderr, "raystack render: %s written after all\n", image.exr.c_str());
      return s;
    }
    wait_s = std::min(30.0, wait_s * 2);
  }
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
    if (image.nothing) {
      if (image.written) image.written();
      lock.lock();
      writing_ = false;
      cv_.notify_all();
      continue;
    }
    auto write = [&](image::ExrThreads threads) {
      try {
        s = WriteImage(image, threads);
      } catch (...) {  // out of this thread: std::terminate; nothing allocated here (status.h)
        s = Status::Error(kOutOfMemory);
      }
      if (image.done) image.done(s);
    };
    if (image.background) {
      // On a thread of its own at nice 19: Linux applies a nice value to one thread, and an
      // unprivileged one cannot raise it back, so this thread stays at the job's priority for
      // the last frame (whose compression threads start from it). A refused nice only leaves
      // the priority where it was.
      try {
        std::thread low([&] {
          SetThreadName("rs-write-low");
          (void)setpriority(PRIO_PROCESS, static_cast<id_t>(gettid()), 19);
          write(image::ExrThreads::kCallingThread);
        });
        low.join();
      } catch (const std::system_error&) {  // no thread to be had (a limit): on this one
        write(image::ExrThreads::kCallingThread);
      }
    } else {
      write(image::ExrThreads::kAllCores);
    }
    if (!image.done && s.ok() && announce_)
      std::printf("  wrote %s\n", image.png_only ? image.png.c_str() : image.exr.c_str());
    if (!image.done && s.ok() && image.written) image.written();
    lock.lock();
    spare_ = std::move(image.layers);  // a frame's or a checkpoint's: the next resolve's memory
    writing_ = false;
    // The first failed frame image is the error; those written after it fails too (an
    // interrupt ended the first's retries with the next one queued) are named in it, so the
    // job's last message lists every frame rendered and not written.
    if (!image.done && !s.ok())
      error_ = error_.ok() ? s
                           : Status::Error(error_.message() + "; " + image.exr +
                                           " is not written either");
    cv_.notify_all();
  }
}

}  // namespace raystack::master
