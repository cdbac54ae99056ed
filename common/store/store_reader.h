#pragma once
// Opens a block store: reads and verifies index.bin and octree.bin whole (they are small and
// always in RAM), and reads single blocks on request from blocks.bin with pread, so one
// StoreReader serves any number of threads. Every error names the file and the block.

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "common/store/block_codec.h"
#include "common/store/block_view.h"
#include "common/store/format.h"
#include "common/store/octree.h"

namespace raystack::store {

// O_DIRECT wants the file offset, the length and the memory aligned to the device's logical
// block size; 4096 covers every common device (512-byte ones too).
inline constexpr uint64_t kDirectAlign = 4096;

// What a direct read of [offset, offset + size) reads: the aligned span around it.
struct DirectSpan {
  uint64_t begin = 0, end = 0;  // aligned
  uint64_t skip = 0;            // the range's first byte in the span
  uint64_t needed = 0;          // bytes the span must get: the file may end inside its last unit
};
inline DirectSpan DirectSpanOf(uint64_t offset, uint64_t size) {
  DirectSpan s;
  s.begin = offset / kDirectAlign * kDirectAlign;
  s.end = (offset + size + kDirectAlign - 1) / kDirectAlign * kDirectAlign;
  s.skip = offset - s.begin;
  s.needed = s.skip + size;
  return s;
}

// Where a direct read lands: aligned memory, grown to the largest span asked for, so reads
// do not allocate once it has grown.
class DirectBuffer {
 public:
  uint8_t* Reserve(uint64_t bytes);
  uint8_t* data() { return data_.get(); }

 private:
  struct Free {
    void operator()(uint8_t* p) const;
  };
  std::unique_ptr<uint8_t, Free> data_;
  uint64_t capacity_ = 0;
};

// When `dir` holds no store at all (nothing there, a file such as a model, a folder without
// index.bin): why, and what to do, for messages; empty when it may hold one.
std::string NoStoreThere(const std::string& dir);

class StoreReader {
 public:
  // Opens the store in directory `dir`, verifying headers, versions, checksums and the octree.
  static Expected<std::unique_ptr<StoreReader>> Open(const std::string& dir);
  ~StoreReader();
  StoreReader(const StoreReader&) = delete;
  StoreReader& operator=(const StoreReader&) = delete;

  const std::string& dir() const { return dir_; }
  const StoreSummary& summary() const { return summary_; }
  std::span<const BlockEntry> blocks() const { return blocks_; }
  std::span<const MaterialRecord> materials() const { return materials_; }
  // The emissive triangles (lights.bin). Empty, with lights_listed() false, for a store written
  // before lights.bin existed: its emitters are only found by the rays that meet them.
  std::span<const EmitterRecord> emitters() const { return emitters_; }
  bool lights_listed() const { return lights_listed_; }
  OctreeView octree() const { return OctreeView(nodes_, NodeBoundsView(), root_cell()); }
  Bounds3f root_cell() const;
  Bounds3f model_bounds() const;
  uint64_t blocks_file_bytes() const { return blocks_file_bytes_; }

  // Where blocks first..last (consecutive ids, neighbours in blocks.bin) lie: from the first's
  // offset to the end of the last, what one read of the run covers.
  struct Extent {
    uint64_t offset, size;
  };
  Extent RunExtent(uint32_t first, uint32_t last) const {
    const uint64_t begin = blocks_[first].offset;
    return {begin, blocks_[last].offset + blocks_[last].stored_bytes - begin};
  }
  // Reads `size` bytes of blocks.bin at `offset` (a loader reading a run of neighbouring blocks
  // in one request). Errors name the file and offset. Thread-safe.
  Status ReadRange(uint64_t offset, uint64_t size, uint8_t* out) const;
  // The error ReadRange gives for a range past the end of blocks.bin, else ok.
  Status CheckRange(uint64_t offset, uint64_t size) const;
  // From now on ReadRange reads past the page cache (O_DIRECT). For a store larger than the
  // memory the page cache could keep, the kernel's copy of each block is only a cost: it is
  // inserted, copied out, and reclaimed soon after (under a cgroup memory limit, by the
  // reading thread itself). Fails, naming the file, when its filesystem does not take direct
  // reads (checked with a first read); ReadRange stays buffered then. Call before any reader
  // thread starts.
  Status UseDirectReads();
  bool direct_reads() const { return direct_fd_ >= 0; }
  // blocks.bin opened O_DIRECT (-1 before UseDirectReads), for a reader that keeps its reads
  // in flight itself (slave/aio_runs.h); reads must be kDirectAlign-aligned.
  int direct_fd() const { return direct_fd_; }
  // Reads block `id`'s stored bytes (for a loader that batches reads). Thread-safe.
  Status ReadStored(uint32_t id, std::vector<uint8_t>* stored) const;
  // Verifies the checksum, decompresses into `raw` and validates. Thread-safe.
  Expected<BlockView> Decode(uint32_t id, std::span<const uint8_t> stored, AlignedBuffer* scratch,
                             AlignedBuffer* raw) const;
  // ReadStored + Decode.
  Expected<BlockView> Load(uint32_t id, std::vector<uint8_t>* stored, AlignedBuffer* scratch,
                           AlignedBuffer* raw) const;

 private:
  StoreReader() = default;
  Status ReadIndex();
  Status ReadOctree();
  Status ReadLights();
  void ComputeNodeBounds();
  Status OpenBlocks();
  Status ReadRangeDirect(uint64_t offset, uint64_t size, uint8_t* out) const;
  std::string BlockError(uint32_t id, const std::string& what) const;

  std::string dir_;
  StoreSummary summary_{};
  std::vector<MaterialRecord> materials_;
  std::vector<BlockEntry> blocks_;
  std::vector<OctreeNode> nodes_;
  std::vector<EmitterRecord> emitters_;
  bool lights_listed_ = false;
  // Per node, the union of its blocks' bounds: lower x, y, z then upper x, y, z, each an array
  // of node_count floats (NodeBounds).
  std::vector<float> node_bounds_;
  NodeBounds NodeBoundsView() const;
  int blocks_fd_ = -1;
  int direct_fd_ = -1;  // blocks.bin again, opened with O_DIRECT (UseDirectReads)
  uint64_t blocks_file_bytes_ = 0;
};

}  // namespace raystack::store
