#pragma once
// The render's output file: all layers of an ImageLayers in one OpenEXR file, readable by any
// EXR viewer or compositor (channels named as they expect: R G B A Z, N.X..., albedo.R...).
// This library is the only place OpenEXR is linked; its exceptions never leave it. Both
// functions may be called from several threads at once (OpenEXR has one process-wide pool of
// threads, sized for each file: see exr_pool.h).

#include <string>

#include "common/base/status.h"
#include "common/image/exr_pool.h"  // ExrThreads
#include "common/image/image_layers.h"
#include "common/base/output_file.h"  // CheckWritable, for the callers of WriteExr

namespace raystack::image {

// Writes all layers as one scanline EXR (channels R G B A Z N.X N.Y N.Z albedo.R albedo.G
// albedo.B samples (UINT) variance; FLOAT for the rest; ZIP compression), atomically: a temp
// file in the same folder then rename, so a reader never sees half a file. Errors name the path.
// rgba is required; any other layer may be empty, and its channels are then left out. A layer
// that is neither empty nor exactly the image's size is an error.
// Chunks are compressed on every core (kAllCores, for a file the user waits for; OpenEXR's
// threads are started from the calling thread and take its priority) or on the calling thread
// alone (kCallingThread, for one written while rendering goes on: at that thread's priority);
// the file is byte for byte the same.
Status WriteExr(const std::string& path, const ImageLayers& image,
                ExrThreads threads = ExrThreads::kAllCores);

// Reads a file written by WriteExr (or any EXR with at least R G B; missing layers left empty;
// a missing A reads as 1), decompressed in bands of rows on threads of its own (one per core).
// Errors name the path (missing file, not an EXR, truncated). A header
// claiming more than 2^28 pixels (16384 x 16384) or a side above 65536 is refused rather than
// allocated: a damaged file must not take the machine's memory.
Expected<ImageLayers> ReadExr(const std::string& path);
// The same into `image`, whose layers' memory is used again where large enough (each frame's
// reference read into the last one's: new memory costs a page fault a page). On failure
// `image` holds no usable image.
Status ReadExrInto(const std::string& path, ImageLayers* image);
// Whether the EXR at `path` is a raystack frame not finished ("raystack.state" "partial": a
// checkpoint), from its header alone; false for a missing file, or one another program wrote.
bool IsPartialFrame(const std::string& path);

}  // namespace raystack::image
