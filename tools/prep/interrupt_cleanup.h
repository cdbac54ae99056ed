#pragma once
// Ctrl-C (SIGINT) or SIGTERM while raystack-prep converts: what the conversion wrote is removed
// (the store's temporaries, which may hold gigabytes, and its work folder of bucket files), a
// store that was there before stays as it was, and the process says so before it ends with the
// shell's code for the signal (130, 143). It used to end silently, leaving all of that behind.
// The signals are taken by a thread of their own (sigwait): the conversion's threads need no
// polling, and the clean-up is ordinary code, not a signal handler's.

#include <cstdint>
#include <functional>
#include <string>

namespace raystack::prep {

// Blocks SIGINT and SIGTERM in the calling thread, and so in every thread it starts later, and
// starts the thread that takes them. `output`: the store being written, for the message. Call
// once, before any other thread starts.
void CleanUpOnInterrupt(const std::string& output);

// Once the new store is complete (StoreWriter::Finish succeeded): an interrupt after it says
// the store was replaced, not that it is as it was.
void NoteStoreWritten();

// A clean-up that runs if an interrupt comes while this lives; it returns what it could not
// do, said to the user (empty: done). The destructor waits for one that is running (the
// process then ends).
class OnInterrupt {
 public:
  explicit OnInterrupt(std::function<std::string()> clean);
  ~OnInterrupt();
  OnInterrupt(const OnInterrupt&) = delete;
  OnInterrupt& operator=(const OnInterrupt&) = delete;

 private:
  uint64_t id_;
};

}  // namespace raystack::prep
