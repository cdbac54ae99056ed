#pragma once
// Vertex attributes by index, for resolving faces while streaming. A table keeps its records in
// RAM while the shared MemoryBudget grants pages; when the budget refuses one, the table moves
// everything to a file in a private TempDir and from then on serves lookups through a small
// direct-mapped page cache of its own. So memory stays bounded whatever the vertex count:
// at most the budget, plus kCachePages + 1 pages per spilled table.
// Not thread-safe: one reader owns its tables.

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "common/base/temp_dir.h"

namespace raystack::import {

// Bytes that the vertex tables of one read may keep in RAM. Refusal is not an error.
class MemoryBudget {
 public:
  explicit MemoryBudget(uint64_t bytes) : limit_(bytes) {}
  bool TryReserve(uint64_t bytes) {
    if (bytes > limit_ - used_) return false;
    used_ += bytes;
    return true;
  }
  void Release(uint64_t bytes) { used_ -= bytes; }
  uint64_t used() const { return used_; }

 private:
  uint64_t limit_;
  uint64_t used_ = 0;
};

class VertexTable {
 public:
  // Pages are the unit of budget, of spill I/O and of caching. A record never straddles two.
  static constexpr size_t kPageBytes = size_t{64} << 10;
  // Faces mostly reference recent vertices, so a few pages catch nearly all lookups.
  static constexpr size_t kCachePages = 16;
  static constexpr int kMaxFloatsPerVertex = 16;
  static_assert((kCachePages & (kCachePages - 1)) == 0, "cache slots are page % kCachePages");

  // Records of `floats_per_vertex` floats; RAM pages come from `budget` (which must outlive
  // the table); a spill file goes in a fresh TempDir under `temp_parent` ("" = $TMPDIR).
  VertexTable(int floats_per_vertex, MemoryBudget* budget, std::string temp_parent);
  ~VertexTable();
  VertexTable(const VertexTable&) = delete;
  VertexTable& operator=(const VertexTable&) = delete;

  // Adds record size(); fails only when the spill file cannot be created or written.
  Status Append(const float* values);
  // Copies record `index` (< size()) to `out`; fails only when the spill file cannot be read.
  Status Get(uint64_t index, float* out);

  uint64_t size() const { return size_; }
  bool spilled() const { return fd_ >= 0; }
  int floats_per_vertex() const { return floats_; }

 private:
  Status StartNewPage();
  Status Spill();
  Status FlushTailPage();
  Status GetSpilled(uint64_t page, size_t slot, float* out);

  int floats_;
  size_t records_per_page_;
  MemoryBudget* budget_;
  std::string temp_parent_;
  uint64_t size_ = 0;

  // In RAM: every page, the last one partly filled.
  std::vector<std::unique_ptr<float[]>> ram_pages_;

  // Spilled: pages [0, flushed_pages_) are in the file; the partly filled one is tail_.
  std::optional<TempDir> temp_dir_;
  int fd_ = -1;
  uint64_t flushed_pages_ = 0;
  std::unique_ptr<float[]> tail_;
  std::unique_ptr<float[]> cache_;       // kCachePages pages
  std::vector<uint64_t> cache_tags_;     // page held by each slot, or kNoPage
};

inline Status VertexTable::Get(uint64_t index, float* out) {
  uint64_t page = index / records_per_page_;
  size_t slot = static_cast<size_t>(index % records_per_page_);
  if (!spilled()) {
    std::memcpy(out, ram_pages_[page].get() + slot * floats_, sizeof(float) * floats_);
    return OkStatus();
  }
  return GetSpilled(page, slot, out);
}

}  // namespace raystack::import
