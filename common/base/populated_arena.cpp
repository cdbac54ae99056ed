#include "common/base/populated_arena.h"

#include <sys/mman.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <iterator>

#include "common/base/check.h"
#include "common/base/populate.h"
#include "common/base/log.h"

namespace raystack {

PopulatedArena::PopulatedArena(uint64_t capacity) {
  capacity_ = std::max<uint64_t>((capacity + kStep - 1) / kStep * kStep, kStep);
  void* p = mmap(nullptr, capacity_, PROT_READ | PROT_WRITE,
                 MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
  if (p == MAP_FAILED) {  // no address space for it (a strict overcommit policy, a ulimit -v)
    LOG_WARNING("memory", "no %llu MB of address space for a block arena (%s): its buffers "
                "come from the heap", static_cast<unsigned long long>(capacity_ >> 20),
                std::strerror(errno));
    capacity_ = 0;
    return;
  }
  base_ = static_cast<uint8_t*>(p);
  // Ordinary pages even where the kernel gives huge pages unasked (transparent huge pages
  // "always"): see the top of populated_arena.h.
  madvise(base_, capacity_, MADV_NOHUGEPAGE);
}

PopulatedArena::~PopulatedArena() {
  if (base_ != nullptr) munmap(base_, capacity_);
}

uint8_t* PopulatedArena::Allocate(uint64_t bytes) {
  CHECK(bytes > 0);
  const uint64_t size = Rounded(bytes);
  std::lock_guard lock(mu_);
  auto best = free_by_size_.lower_bound({size, 0});
  uint64_t offset;
  if (best != free_by_size_.end()) {
    const auto [piece, at] = *best;
    RemoveFree(at, piece);
    if (piece > size) AddFree(at + size, piece - size);
    offset = at;
  } else if (capacity_ - top_ >= size) {
    offset = top_;
    top_ += size;
    PopulateTo(top_);
  } else {
    return nullptr;
  }
  allocated_ += size;
  return base_ + offset;
}

void PopulatedArena::Free(uint8_t* p, uint64_t bytes) {
  CHECK(Owns(p));
  uint64_t offset = static_cast<uint64_t>(p - base_);
  uint64_t size = Rounded(bytes);
  std::lock_guard lock(mu_);
  allocated_ -= size;
  // Merge with the free neighbours, so that freed room serves larger pieces again.
  auto next = free_by_offset_.lower_bound(offset);
  if (next != free_by_offset_.end() && next->first == offset + size) {
    const auto [at, piece] = *next;
    RemoveFree(at, piece);
    size += piece;
  }
  next = free_by_offset_.lower_bound(offset);
  if (next != free_by_offset_.begin()) {
    const auto [at, piece] = *std::prev(next);
    if (at + piece == offset) {
      RemoveFree(at, piece);
      offset = at;
      size += piece;
    }
  }
  if (offset + size == top_) {
    top_ = offset;  // back to the untouched end (its pages stay populated)
  } else {
    AddFree(offset, size);
  }
}

uint64_t PopulatedArena::allocated_bytes() const {
  std::lock_guard lock(mu_);
  return allocated_;
}

uint64_t PopulatedArena::populated_bytes() const {
  std::lock_guard lock(mu_);
  return populated_;
}

void PopulatedArena::PopulateTo(uint64_t end) {
  if (end <= populated_) return;
  const uint64_t target = std::min(capacity_, (end + kStep - 1) / kStep * kStep);
  // Fails before Linux 5.14 (EINVAL) and without memory (ENOMEM): the pages then come one
  // fault at a time when first written, and a real lack of memory shows there as it would.
  madvise(base_ + populated_, target - populated_, kMadvPopulateWrite);
  populated_ = target;
}

void PopulatedArena::AddFree(uint64_t offset, uint64_t size) {
  free_by_offset_.emplace(offset, size);
  free_by_size_.emplace(size, offset);
}

void PopulatedArena::RemoveFree(uint64_t offset, uint64_t size) {
  free_by_offset_.erase(offset);
  free_by_size_.erase({size, offset});
}

}  // namespace raystack
