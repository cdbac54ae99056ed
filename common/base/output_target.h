#pragma once
// Where a file of figures given on the command line goes (render's --stats, prep's
// --stats-json): the file it names (a link followed), or a stream written in place (a pipe, a
// terminal, /dev/null, or this process's own standard output or error, even when that is a
// regular file: written in order, at its own offset, never replaced: a review found
// /dev/stdout sent to a file replaced by the figures, the run's text gone with the old file).

#include <string>

namespace raystack {

struct OutputTarget {
  std::string path;     // the file written (or locked), a link followed
  bool stream = false;
  int std_fd = -1;      // 1 or 2 when it is this process's standard output or error
};
OutputTarget ResolveOutputTarget(const std::string& given);

// A stream target opened for writing: a copy of the standard descriptor, or the path opened
// without waiting for a reader (O_NONBLOCK, cleared once open: a FIFO that no program reads
// held the job in open(), deaf to a first Ctrl-C; a hostile-input review). -1 and *why if not.
int OpenStream(const OutputTarget& target, std::string* why);

}  // namespace raystack
