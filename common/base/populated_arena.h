#pragma once
// Memory for many mid-sized buffers that live and die in no particular order (a block cache's
// decoded blocks): one reservation of address space, handed out in 64-byte aligned pieces,
// with freed pieces merged with their free neighbours and reused best fit.
//
// Why not the C heap: every 4 KB page it gives out for the first time is a page fault, and in
// a virtual machine that keeps the guest's page tables itself (a PVM guest, as on the
// 2026-11-25 machines) each fault leaves the guest: ~11 us a page, 0.2 s of CPU to fill a
// 72 MB cache. Here the pages are mapped 2 MB at a time in one call, before anything touches
// them (madvise MADV_POPULATE_WRITE).
//
// Ordinary 4 KB pages, not huge pages (advised so): where a VM's host takes freed memory back
// (Linux free page reporting), memory new to the guest populated as huge pages came at ~500
// MB/s against ~3 GB/s as 4 KB pages, and 8 slaves filling their caches paid it in their first
// frame; the ray threads trace a block's queue within its ~32 KB, so the TLB's reach cost
// nothing measurable (tools/bench/RESULTS.md, "The block cache on 4 KB pages").
//
// Address space only becomes memory as the high-water mark of the pieces grows, a 2 MB step
// at a time, so a large capacity costs nothing until it is used. Allocate returns null when no
// piece fits (full, or free room too fragmented); callers then take the C heap. Where the
// kernel has no MADV_POPULATE_WRITE (before Linux 5.14) the advice fails and pages come one
// fault at a time, as from the heap.
//
// Thread-safe: one mutex, held for a few map operations per call.

#include <cstdint>
#include <map>
#include <mutex>
#include <set>
#include <utility>

namespace raystack {

class PopulatedArena {
 public:
  static constexpr uint64_t kAlignment = 64;
  static constexpr uint64_t kStep = uint64_t{2} << 20;  // populated at a time

  // Reserves `capacity` bytes of address space (rounded up to kStep). Where the system refuses
  // even that, logs it, and the arena has no room: every Allocate returns null.
  explicit PopulatedArena(uint64_t capacity);
  ~PopulatedArena();
  PopulatedArena(const PopulatedArena&) = delete;
  PopulatedArena& operator=(const PopulatedArena&) = delete;

  // `bytes` (> 0) of kAlignment-aligned memory, or null when no free piece is large enough.
  uint8_t* Allocate(uint64_t bytes);
  // Gives back a piece from Allocate with the same `bytes`.
  void Free(uint8_t* p, uint64_t bytes);
  // Whether `p` lies in this arena.
  bool Owns(const uint8_t* p) const { return p >= base_ && p < base_ + capacity_; }

  uint64_t capacity() const { return capacity_; }
  uint64_t allocated_bytes() const;  // in pieces handed out now
  uint64_t populated_bytes() const;  // memory the arena has asked the kernel for so far

 private:
  static uint64_t Rounded(uint64_t bytes) { return (bytes + kAlignment - 1) & ~(kAlignment - 1); }
  void PopulateTo(uint64_t end);  // mu_ held
  void AddFree(uint64_t offset, uint64_t size);     // mu_ held
  void RemoveFree(uint64_t offset, uint64_t size);  // mu_ held

  uint8_t* base_ = nullptr;
  uint64_t capacity_ = 0;
  mutable std::mutex mu_;
  uint64_t top_ = 0;  // everything from here to capacity_ is free and never handed out
  uint64_t populated_ = 0;
  uint64_t allocated_ = 0;
  std::map<uint64_t, uint64_t> free_by_offset_;            // free pieces below top_: offset -> size
  std::set<std::pair<uint64_t, uint64_t>> free_by_size_;  // the same as (size, offset), best fit
};

}  // namespace raystack
