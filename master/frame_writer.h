#pragma once
// Writes finished frames' images (EXR, and the PNG quick look) on a thread of its own, so the
// next frame renders while the last one is compressed and written. Written on the master's
// thread between frames, a 960x540 EXR took ~0.4 s in which every slave waited for its first
// tile of the next frame: half a frame at 8 slaves. At most one image waits while another is
// written (Write waits for room), so a slow disk slows the job rather than fill memory.
//
// An image written while later frames render (`background`) is compressed on one thread at the
// lowest priority (nice 19), started for it: it takes the cores the render leaves idle instead
// of taking them from the render. On a 2-core machine with 8 slaves at 20% of a core, the
// compression of a 1920x1080 frame (0.58 CPU-s on both cores) otherwise slowed the next frame by
// ~6% (tools/bench/RESULTS.md). The last frame, which the user waits for, is compressed on every
// core at the job's priority; by then nothing else runs.
//
// Checkpoints (master/checkpoints.h) go through the same queue, so a frame's checkpoints are
// always written before its final image, which replaces them at the same path. Only one thread
// queues images.
//
// A frame's image that cannot be written (a full disk, its folder removed) is tried again, at
// 1, 2, 4 ... up to 30 s apart, for kRetrySeconds, saying so, until it is written, SIGINT or
// SIGTERM comes, or the time is up: it is the frame's only copy, and failing at once lost a
// finished frame to a disk that a user could have cleared in a minute.

#include <condition_variable>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "common/base/status.h"
#include "common/image/exr_pool.h"
#include "common/image/image_layers.h"

namespace raystack::master {

class FrameWriter {
 public:
  struct Image {
    std::string exr;
    std::string png;  // empty: no PNG
    // The EXR is already there, whole (--resume of a complete frame whose PNG is missing): only
    // the PNG is written, so the EXR keeps its time and a compositor does not reload it.
    bool png_only = false;
    float exposure = 0;
    bool background = false;  // later frames render while it is written
    image::ImageLayers layers;
    // Set for a checkpoint: called with the write's result by the thread that wrote it, which then
    // is not the writer's error (a failed checkpoint is retried, never the end of the job),
    // and nothing is announced.
    std::function<void(const Status&)> done;
    // A frame's image (not a checkpoint): called by the writer's thread once it is written
    // (--stats' record of the frame goes then: a record says its image is on disk).
    std::function<void()> written;
    // Nothing to write (a complete frame --resume keeps as it is): only `written` is called, in
    // its turn after the frames queued before it (their records stay in frame order).
    bool nothing = false;
  };
  static constexpr double kRetrySeconds = 600;

  // announce: print "  wrote PATH" once an EXR is written. fail_first (a fault for tests): the
  // first that many writes of frame images fail, as on a full disk. retry_seconds: how long a
  // frame's image is tried again. slow_s (a fault for tests): each frame image's write first
  // waits that long, as on a slow disk, so the writer falls behind the render.
  explicit FrameWriter(bool announce, int64_t fail_first = 0, double retry_seconds = kRetrySeconds,
                       double slow_s = 0);
  // Writes what is queued, then ends (what it had to write is never lost).
  ~FrameWriter();
  FrameWriter(const FrameWriter&) = delete;
  FrameWriter& operator=(const FrameWriter&) = delete;

  // Queues `image` once the writer has taken the one before it; the first failed write so
  // far, if any (then `image` is not queued).
  Status Write(Image image);
  // Whether Write would queue an image at once (nothing is waiting to be taken).
  bool HasRoom();
  // Waits until everything queued is written; the first failed write, if any.
  Status Finish();
  // The layers of the last image written (a frame's or a checkpoint's), handed back for the next
  // resolve (a frame's end, a checkpoint) to use: memory already mapped, where a new image costs
  // a page fault a page (~40 ms for 960x540 on a VM that returns freed memory to its host).
  // Empty when there is none, or when it was taken and not written back yet.
  image::ImageLayers TakeSpare();

 private:
  void Loop();
  // Writes `image` (EXR, then PNG); a frame's image is tried again as said above.
  Status WriteImage(const Image& image, image::ExrThreads threads);
  const bool announce_;
  int64_t fail_first_;  // (writer thread only)
  const double retry_seconds_;
  const double slow_s_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::optional<Image> queued_;  // (under mu_)
  image::ImageLayers spare_;     // (under mu_)
  bool writing_ = false, stop_ = false;
  Status error_;
  std::thread thread_;
};

}  // namespace raystack::master
