#pragma once
// Output files that appear whole or not at all: written under a temporary name in the target's
// folder, then renamed over the target (rename is atomic within one file system), so a viewer
// or a later pipeline step never reads half an image, and a failed write leaves the previous
// file in place.

#include <cstdint>
#include <string>
#include <utility>

#include "common/base/follow_links.h"
#include "common/base/status.h"

namespace raystack {

// Checks before a render starts that `path` can be written (folder exists and is writable); an
// error naming the path otherwise. (It creates and removes a temporary file there: the only
// test that sees read-only mounts and ACLs as they are.)
Status CheckWritable(const std::string& path);

// Checks before a render starts that the file system holding `path` has `bytes` free (for the
// images a render will write): a full disk is reported then, naming the path, the room there
// is and the room needed, not after hours of rendering.
Status CheckRoom(const std::string& path, uint64_t bytes);
// The bytes free for this user on the file system holding `path` (its folder), or why not.
Expected<uint64_t> FreeSpace(const std::string& path);

// Removes the temporaries of `path` (AtomicOutput's, ".NAME.tmp-HOST-PID-N") that a process no
// longer running on this machine left, killed while it wrote: each as large as the image.
// Other machines' are left alone (a shared folder). Returns how many.
int RemoveStaleTemporaries(const std::string& path);

// A temporary file beside `path` (links followed); Commit() makes it the file. Destroyed without a successful
// Commit(), it removes the temporary. Move-only; not thread-safe.
class AtomicOutput {
 public:
  // Creates the (empty) temporary file. Errors name `path`.
  static Expected<AtomicOutput> Create(const std::string& path);
  AtomicOutput(AtomicOutput&& other) noexcept;
  AtomicOutput& operator=(AtomicOutput&&) = delete;
  AtomicOutput(const AtomicOutput&) = delete;
  ~AtomicOutput();

  // Where the writer writes (by name; the file exists and is empty).
  const std::string& temp_path() const { return temp_path_; }
  const std::string& path() const { return path_; }
  // Flushes the temporary to disk and renames it to path().
  Status Commit();

 private:
  AtomicOutput(std::string path, std::string temp_path)
      : path_(std::move(path)), temp_path_(std::move(temp_path)) {}
  std::string path_;
  std::string temp_path_;  // empty once committed or moved from
};

}  // namespace raystack
