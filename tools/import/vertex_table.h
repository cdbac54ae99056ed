#pragma once
// Vertex attributes by index, for resolving faces while streaming. A table keeps its records in
// RAM while the shared MemoryBudget grants pages; when the budget refuses one, the table moves
// everything to a file in a private TempDir and from then on serves lookups through a
// direct-mapped cache of 4 KB lines of its own, as large as half the budget then free (at least
// kMinCacheLines). So memory stays bounded whatever the vertex count: at most the budget, plus
// kMinCacheLines lines and a page per spilled table.
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
  uint64_t limit() const { return limit_; }

 private:
  uint64_t limit_;
  uint64_t used_ = 0;
};

class VertexTable {
 public:
  // Pages are the unit of budget, of spill I/O and of caching. A record never straddles two.
  static constexpr size_t kPageBytes = size_t{64} << 10;
  // Once spilled, lookups read 4 KB lines: a model whose faces reference its vertices in no
  // order missed on nearly every lookup, and read a 64 KB page each time (a 12.5 M-triangle
  // scan read at 1.8 MB/s; a converter persona).
  static constexpr size_t kLineBytes = size_t{4} << 10;
  static constexpr size_t kMinCacheLines = 256;  // 1 MB: faces mostly reference recent vertices
  static constexpr int kMaxFloatsPerVertex = 16;

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
  // The cached copy of line `line` of the spill file (read on a miss).
  Expected<const char*> Line(uint64_t line);

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
  std::unique_ptr<char[]> cache_;        // cache_lines_ lines
  size_t cache_lines_ = 0;
  uint64_t cache_reserved_ = 0;          // of the budget, for lines beyond kMinCacheLines
  std::vector<uint64_t> cache_tags_;     // line held by each slot, or kNoLine
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
