#pragma once
// What a render checks before it starts, so that trouble it would meet at the end of a long
// render (an output it cannot write, a disk without room, a film larger than the memory, a
// reference image missing for a later camera) is reported at its start, naming the file.

#include <cstddef>
#include <cstdint>
#include <string>

#include "common/base/status.h"
#include "common/render/scene.h"
#include "common/store/store_reader.h"
#include "slave/render_engine.h"

namespace raystack::master {

// Frame `frame`'s file of `frames` from the output path: out.exr -> out-1.exr for the second
// camera (out.exr itself when there is one), the number with as many digits as the last frame's
// (out-01.exr of 12 frames), `ext` in place of the extension (.exr, .png). With several
// cameras, a file name with a run of '#' or a printf-style %d / %04d gets the number there
// instead, that many digits (f.####.exr -> f.0001.exr), for image-sequence tools; one camera's
// name is kept as given (take#2.exr stays).
std::string FramePath(const std::string& path, size_t frame, size_t frames, const char* ext);

// The cameras a run renders: [begin, end) of the scene's list (--frames; every one by default).
struct FrameRange {
  size_t begin = 0, end = 0;
};

// The output names the EXR (an .exr path, not a folder); every frame's image in `frames` can
// be written there, PNGs too when `png`, and the disk has room for the largest (twice with
// `checkpoints`: a checkpoint's temporary sits beside the previous one). Room for all of them
// at their largest (uncompressed; files they replace count as room) is only warned of: EXR compression usually
// needs far less, and a frame that meets a full disk is tried again while space is freed (a
// 500-frame job was refused 99 MB it would have written in 27). Removes the temporaries a
// killed run left there.
Status CheckOutputs(const render::Scene& scene, const std::string& output, bool png,
                    bool checkpoints, FrameRange frames);

// The film and the images made from it fit in this machine's memory (or its cgroup's): a
// 16384 x 16384 frame needs ~55 GB, and running out midway ended the job with an uncaught
// std::bad_alloc. `cache_bytes`: the decoded blocks this process will hold where it renders
// too (0 for a master alone, or before the store is opened), said as `what`, and what to do
// instead, `advice`.
Status CheckMemory(const render::Scene& scene, uint64_t cache_bytes,
                   const std::string& what = "the blocks",
                   const std::string& advice = "a smaller --cache-mb would fit");

// Every camera's reference image (`reference`, REF-f.exr with several cameras) can be read:
// checked before the first frame rather than when its frame comes (its size is checked then).
Status CheckReferences(const render::Scene& scene, const std::string& reference, FrameRange frames);

// The memory one process's engine holds beside its film: its blocks (every one in core, else at
// most its cache) and, in --mode bvh, the one tree over every triangle at its peak while it is
// built (a job that did not count it was killed by the kernel as it built it, without a word).
struct EngineMemory {
  uint64_t bytes = 0;
  std::string what;    // "the blocks (--cache-mb)", ...
  std::string advice;  // what would fit
};
EngineMemory EngineMemoryOf(const slave::EngineOptions& engine, const store::StoreReader& store);

// A slave's engine fits in its machine's memory (or its cgroup's): refused, naming the host,
// before it starts, not killed by the kernel midway (seen by the master only as a silent rank).
// `slaves_here` slaves share that machine, each with the same engine: all of them must fit
// (they check at the same moment, so each alone would see the room the others will take).
Status CheckSlaveMemory(const EngineMemory& m, int slaves_here, const std::string& host);

}  // namespace raystack::master
