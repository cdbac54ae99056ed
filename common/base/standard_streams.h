#pragma once
// The standard streams of a command-line tool, at its start and its end.

namespace raystack {

// Opens /dev/null on each of descriptors 0, 1 and 2 that is closed (`tool >&-`): otherwise the
// next file the tool opens takes that number, and what it prints lands in that file (a store,
// an image being written).
void OpenClosedStandardStreams();

// Flushes the standard output and returns `code`, or 1 when what was printed did not all reach
// it (a full disk, /dev/full), said on stderr as `tool`'s: raystack-info's report is its
// product, and it was lost with exit 0 (a pipeline review).
int EndWithStandardOutput(const char* tool, int code);

}  // namespace raystack
