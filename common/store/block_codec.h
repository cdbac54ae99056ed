#pragma once
// Raw block <-> stored block. Stored = lz4(byte_shuffle(raw)): the shuffle transposes the raw
// bytes as 4-byte words into four byte planes (all first bytes, then all second bytes, ...),
// which puts the slowly varying sign/exponent bytes of neighbouring floats together: on the
// dragon lz4 alone gives 1.34x, shuffled 1.55x (tools/bench/RESULTS.md; the design brief had
// hoped for ~2.0x). Each stored block has an XXH3-64 checksum.

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "common/base/populated_arena.h"
#include "common/base/status.h"

namespace raystack::store {

// XXH3-64 of a byte range.
uint64_t Checksum(std::span<const uint8_t> bytes);

// Compresses `raw` (size a multiple of 4) into `stored` (resized). `shuffle` = false stores
// plain lz4 (for measurement).
void EncodeBlock(std::span<const uint8_t> raw, std::vector<uint8_t>* stored, bool shuffle = true);
// The most bytes EncodeBlock can produce for a raw block of `raw_bytes` (lz4's bound).
uint64_t MaxStoredBytes(uint32_t raw_bytes);

// A 64-byte aligned byte buffer that only grows: one per thread, reused across blocks. Its
// memory comes from the C heap, or from an arena it is given (a block cache's decoded blocks).
class AlignedBuffer {
 public:
  uint8_t* data() { return data_.get(); }
  const uint8_t* data() const { return data_.get(); }
  uint64_t capacity() const { return capacity_; }
  void Reserve(uint64_t bytes);
  // Takes `bytes` from `arena` if it has room (the buffer must be empty): later Reserves up to
  // `bytes` then keep that memory. False, and nothing changes, when the arena is full.
  bool ReserveIn(PopulatedArena* arena, uint64_t bytes);

 private:
  struct Free {
    Free() noexcept : arena(nullptr), bytes(0) {}  // the C heap
    Free(PopulatedArena* a, uint64_t n) noexcept : arena(a), bytes(n) {}
    void operator()(uint8_t* p) const;
    PopulatedArena* arena;
    uint64_t bytes;
  };
  std::unique_ptr<uint8_t, Free> data_;
  uint64_t capacity_ = 0;
};

// Decompresses `stored` into `raw_out` (exactly raw_bytes), using `scratch` for the shuffled
// form. Fails (never crashes) on any malformed input; the message is completed by the caller,
// which knows the block id and file.
Status DecodeBlock(std::span<const uint8_t> stored, uint32_t raw_bytes, bool shuffled,
                   AlignedBuffer* scratch, AlignedBuffer* raw_out);

// The byte transposition and its inverse (exposed for tests and benchmarks).
void ShuffleBytes(const uint8_t* in, uint64_t size, uint8_t* out);
void UnshuffleBytes(const uint8_t* in, uint64_t size, uint8_t* out);

}  // namespace raystack::store
