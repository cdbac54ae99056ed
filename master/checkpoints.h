#pragma once
// --checkpoint-s: the film is written to the frame's EXR every few seconds while it renders
// (atomically, so a reader never sees half a file and a crash leaves the last checkpoint), for
// --resume. The film is resolved on the caller's thread (the master's loop: a copy of its sums)
// and written by the frame writer, behind the images queued before it and before the frame's
// final image: written on the loop itself, every checkpoint held up the slaves' tiles and
// pixels for as long as the EXR took (frames 40-55% longer at one checkpoint each 0.2 s, 8
// slaves, tools/bench/RESULTS.md). A checkpoint that cannot be queued at once (the writer is
// still behind) is tried at the next call; one that fails to be written is logged and tried
// again at the next interval, never fatal.

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>

#include "common/render/film.h"
#include "master/frame_writer.h"

namespace raystack::master {

class Checkpoints {
 public:
  // Every `every_s` seconds (0: never) to `path`, through `writer`, with `provenance` (what
  // rendered the frame: image::ImageLayers::provenance). Fault injection:
  // `kill_after` (> 0): the process kills itself with SIGKILL right after its `kill_after`-th
  // checkpoint is written, as a crash of the whole job would; the first `fail_first` writes
  // fail as on a full disk.
  Checkpoints(double every_s, std::string path, std::string provenance, FrameWriter* writer,
              int64_t kill_after = -1, int64_t fail_first = 0);
  // --png: every checkpoint writes the frame's quick-look too (`png`, at `exposure`), so the PNG
  // beside the EXR is always of the same pixels (an interrupted frame written to look at left an
  // earlier run's finished PNG beside it). Empty: no PNG.
  void AlsoPng(std::string png, float exposure) {
    png_ = std::move(png);
    exposure_ = exposure;
  }
  const std::string& png() const { return png_; }

  // Queues a checkpoint of `film` (pixels finished with `spp` samples) when one is due; not
  // over a finished image of an earlier run while no pixel has all its samples (it would be
  // lost for nothing --resume could keep).
  void Maybe(const render::Film& film, uint32_t spp);
  // The job is being interrupted, and the process ends next. First waits until everything
  // queued before is written: the images of frames that finished rendering, which the writer
  // may still hold (it can lag two frames behind), are their frames' only copies (found by an
  // animator: a Ctrl-C with no pixel of the current frame finished ended the process without
  // them, two finished frames lost). Then writes a checkpoint of `film` now, whatever the
  // interval (also with every_s 0), on every core, and waits until it is written. Returns how
  // many pixels have all `spp` samples (those --resume keeps) and whether it was written. With
  // none it is written all the same, for a look at the frame so far (a user's Ctrl-C in the
  // first passes left no image of minutes of work), unless the film has no sample yet or the
  // file there is not a partial frame (KeepsWhatIsThere). An earlier frame's failed write is
  // the error returned.
  struct Kept {
    uint64_t finished = 0;  // pixels with all their samples
    bool written = false;
  };
  Expected<Kept> Final(const render::Film& film, uint32_t spp);

 private:
  // Whether the file at the path is to be kept rather than replaced by a frame with `finished`
  // pixels that have all their samples: none, over a file that is not a partial frame (a
  // finished image of an earlier run; a file another program wrote).
  bool KeepsWhatIsThere(uint64_t finished) const;
  // What the writer's thread updates once a checkpoint is written: shared, so the frame (and
  // this object) may end before its last checkpoint is.
  struct Written {
    int64_t kill_after;
    int64_t count = 0;  // on the writer's thread only
  };
  double every_s_;
  std::string path_;
  std::string provenance_;
  std::string png_;
  float exposure_ = 0;
  FrameWriter* writer_;
  int64_t fail_first_, attempts_ = 0;
  std::shared_ptr<Written> written_;
  std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
};

}  // namespace raystack::master
