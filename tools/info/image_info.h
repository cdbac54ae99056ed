#pragma once
// raystack-info on an image (an EXR `raystack render` wrote): its size, whether the frame is
// finished ("raystack.state"), its samples per pixel and what rendered it. Under
// `mpirun --enable-recovery` the job's exit code is always 0, so this is how a script or a
// scheduler's epilogue tells a finished frame from a checkpoint or a failed job's leftovers,
// without OpenEXR's own tools (not installed by raystack).

#include <string>

namespace raystack::info {

// Prints what `path` holds; returns 0 for a finished frame, 1 otherwise (unreadable, not
// written by raystack, or partial: said on stderr, with what to do).
int ShowImage(const std::string& path);

// Whether the file at `path` starts as an OpenEXR file does (its magic number).
bool LooksLikeExr(const std::string& path);

}  // namespace raystack::info
