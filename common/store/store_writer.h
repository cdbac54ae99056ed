#pragma once
// Writes a block store directory: blocks are appended to blocks.bin in the order given (the
// converter gives them in space-filling-curve order); Finish() writes octree.bin, lights.bin
// and then index.bin. Each file is written under a temporary name, and only once all are are
// they renamed into place, index.bin last: a store directory with an index.bin is always
// complete, and a store being replaced stays whole until the new one is.

#include <cstdint>
#include <cstdio>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "common/geometry/bounds.h"
#include "common/store/format.h"

namespace raystack::store {

struct EncodedBlock {
  uint32_t id = 0;
  std::vector<uint8_t> stored;  // lz4 bytes
  uint32_t raw_bytes = 0;
  uint32_t triangles = 0;
  uint32_t octree_leaf = 0;
  Bounds3f cell;
  Bounds3f bounds;  // the block's BVH root box (BlockEncoder::bounds())
};

class StoreWriter {
 public:
  // Creates `dir` if needed, locks it (the file kLockFile in it: two writers of one store
  // would share its temporaries and leave it corrupt) and starts blocks.bin. A store there is
  // replaced only by Finish(), once the new one is complete. The lock goes with the writer. A writer destroyed before Finish()
  // succeeds (a failed conversion: a full disk) removes its temporaries, and the files,
  // folder and lock file it created; not a store's files or lock that were there before.
  static Expected<std::unique_ptr<StoreWriter>> Create(const std::string& dir);
  // An error if another process is writing the store in `dir` now (OK when `dir` is missing):
  // for a converter to find out before it reads its model, not after.
  static Status CheckNotBeingWritten(const std::string& dir);
  // Whether `dir` may become a store: a new or empty folder, or one holding only a store's
  // files (it is replaced). A folder with other files would get the store's among them, and a
  // later removal of the store would take the user's files with it.
  static Status CheckFolderIsForAStore(const std::string& dir);
  // Whether `dir` can be written, or created (its nearest existing parent is a folder this
  // process may write in), without creating anything: for a converter to find out before it
  // reads its model (a read-only destination was found only after reading it).
  static Status CheckCanWrite(const std::string& dir);
  // Bytes of the .tmp files a conversion into `dir` left there (killed: no clean up), or is
  // writing now (CheckNotBeingWritten tells which).
  static uint64_t LeftoverBytes(const std::string& dir);
  ~StoreWriter();

  // Appends a block; ids must come in order 0, 1, 2, ...
  Status Add(const EncodedBlock& block);
  // Completes the store. `summary`'s counts of blocks, bytes and references are filled here.
  // `emitters`: the emissive triangles (lights.bin), each once.
  Status Finish(StoreSummary summary, std::span<const OctreeNode> octree,
                std::span<const MaterialRecord> materials,
                std::span<const EmitterRecord> emitters = {});

  std::span<const BlockEntry> entries() const { return entries_; }

  // Removes what an unfinished writer wrote, as its destructor would, from any thread (a
  // converter interrupted: tools/prep/interrupt_cleanup.h); waits for Finish's renames, and a
  // Finish that comes after it replaces nothing (the old store stays whole).
  void Abandon();

 private:
  StoreWriter() = default;
  // What the destructor does when Finish() did not succeed.
  void RemovePartialStore();

  std::string dir_;
  bool created_dir_ = false;   // `dir` did not exist before Create
  bool created_lock_ = false;  // nor did its kLockFile
  std::mutex mu_;              // Finish's renames against Abandon
  bool finished_ = false;      // Finish() succeeded
  bool abandoned_ = false;     // Abandon() ran: Finish must not swap (under mu_)
  int lock_fd_ = -1;  // kLockFile, locked
  std::FILE* blocks_ = nullptr;
  uint64_t offset_ = 0;
  std::vector<BlockEntry> entries_;
};

}  // namespace raystack::store
