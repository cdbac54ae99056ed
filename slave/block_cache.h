#pragma once
// The slave's block cache: decoded blocks by id, under a hard byte budget that is never
// exceeded (bytes are reserved before a read starts, and a load waits rather than overshoot).
// Least recently used unpinned blocks are evicted first.
//
// Traversal takes no lock: TryAcquire/Release are one atomic add each on the block's pin count
// (a ray thread pins a block once per queue batch, not per ray). Eviction claims a block by
// swinging its pin count from 0 to a large negative value, which a concurrent TryAcquire sees
// and backs off from, so a pinned block is never freed under a reader.
//
// Decoded blocks live in an arena mapped ahead (common/base/populated_arena.h) of an eighth more
// than the budget, for the gaps between blocks of different sizes; a block that finds no gap
// large enough takes the C heap. On a PVM guest, filling a 72 MB cache from the heap cost its
// loader 0.2 s of CPU in page faults.
//
// Thread-safe. Budgets count decoded bytes (64-byte rounded), the memory blocks really use.

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

#include "common/base/populated_arena.h"
#include "common/base/status.h"
#include "common/store/block_codec.h"
#include "common/store/block_view.h"
#include "common/store/store_reader.h"

namespace raystack::slave {

class BlockCache {
 public:
  static constexpr uint64_t kUnlimited = ~uint64_t{0};

  // Fails when the budget cannot hold the largest block of the store.
  static Expected<std::unique_ptr<BlockCache>> Create(const store::StoreReader& store,
                                                      uint64_t budget_bytes);

  // Pins block `id` if it is resident and returns its view (valid until Release), else null.
  // Lock-free.
  const store::BlockView* TryAcquire(uint32_t id);
  void Release(uint32_t id);
  // The view of resident block `id` without a pin, for an unlimited cache (incore and bvh
  // modes, every block loaded first): it never evicts, so the view stays valid and the three
  // atomic operations of TryAcquire/Release, two on lines every ray thread writes, are saved
  // (the bvh mode looks a block up on every hit). Null if not resident.
  const store::BlockView* ResidentView(uint32_t id) const;

  // Loader side. BeginLoad claims block `id` for loading and reserves its bytes, evicting
  // least recently used unpinned blocks and waiting while everything resident is pinned.
  // With wait = false it returns kNoRoom instead of waiting (the loader first sends off the
  // reads it has reserved room for: they are what will free room).
  enum class Claim { kLoad, kResident, kLoading, kFailed, kNoRoom };
  Claim BeginLoad(uint32_t id, bool wait = true);
  // Decodes `stored` into the reserved room and makes the block resident with `pins` pins
  // already taken (one per ray thread that asked for it); on failure the block is marked
  // failed and the error (naming the block) is returned.
  Status FinishLoad(uint32_t id, std::span<const uint8_t> stored, int pins,
                    store::AlignedBuffer* scratch);
  // A load that could not read its bytes: releases the reservation, marks the block failed
  // with `why`.
  void FailLoad(uint32_t id, const Status& why);
  // Why block `id` failed (its first error, naming it), for whoever asks for it afterwards:
  // every asker reports the same cause, whichever reports first.
  Status FailureOf(uint32_t id) const;
  // Wakes and fails every BeginLoad waiting for room (the render is ending, pins will not be
  // released any more); later BeginLoads fail at once.
  void Shutdown();
  // Allows loads again after Shutdown: the next frame's loader starts (resident blocks stay).
  void Reopen();
  // Waits until a block another thread is loading is resident or failed.
  Claim WaitWhileLoading(uint32_t id);

  // Charge of one block against the budget.
  uint64_t Charge(uint32_t id) const;
  uint64_t budget() const { return budget_; }
  uint64_t used_bytes() const;
  uint64_t peak_bytes() const { return peak_.load(); }
  uint64_t loads() const { return loads_.load(); }         // #C, reloads included
  // #U: blocks loaded, each counted once per frame (frames start with StartFrame), so a
  // frame's figure is the difference across it, like loads().
  uint64_t distinct_loaded() const { return distinct_.load(); }
  void StartFrame();
  uint64_t evictions() const { return evictions_.load(); }
  uint64_t resident_count() const;
  // Bytes of decoded blocks in the arena now (the rest are on the C heap), and its size.
  uint64_t arena_bytes() const { return arena_.allocated_bytes(); }
  uint64_t arena_capacity() const { return arena_.capacity(); }

 private:
  struct Resident {
    store::AlignedBuffer raw;
    store::BlockView view;
  };
  enum State : uint8_t { kAbsent = 0, kLoadingState, kResidentState, kFailedState };
  struct Entry {
    std::atomic<int32_t> pins{0};
    std::atomic<uint8_t> state{kAbsent};
    uint32_t counted_in = 0;  // the frame it was last counted in by distinct_ (under mu_)
    std::atomic<uint64_t> last_use{0};
    uint32_t resident_index = 0;  // position in resident_ (under mu_)
    std::unique_ptr<Resident> data;
  };
  static constexpr int32_t kEvicting = -(1 << 30);

  BlockCache(const store::StoreReader& store, uint64_t budget);
  // Frees unpinned least recently used blocks until `need` more bytes fit, plus a small reserve
  // so that a run of loads does not rescan for every block. Holds mu_. False if impossible now.
  bool MakeRoom(uint64_t need);

  const store::StoreReader& store_;
  const uint64_t budget_;
  PopulatedArena arena_;  // before entries_: the blocks give their memory back to it
  std::vector<Entry> entries_;
  std::atomic<uint64_t> clock_{0};

  mutable std::mutex mu_;
  std::condition_variable changed_;     // a pin dropped to zero, or a load finished
  std::atomic<int> waiting_{0};         // threads waiting on changed_
  bool shutdown_ = false;               // (under mu_)
  uint32_t frame_ = 1;                  // counts StartFrame calls (under mu_)
  uint64_t used_ = 0;                   // resident + reserved bytes (under mu_)
  std::vector<uint32_t> resident_;      // ids of resident blocks (under mu_)
  std::unordered_map<uint32_t, Status> failures_;  // (under mu_)
  void KeepFailure(uint32_t id, const Status& why);  // into failures_, never throws (mu_ held)
  std::atomic<uint64_t> peak_{0};
  std::atomic<uint64_t> loads_{0}, distinct_{0}, evictions_{0};
};

}  // namespace raystack::slave
