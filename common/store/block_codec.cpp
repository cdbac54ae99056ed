#include "common/store/block_codec.h"

#include <lz4.h>
#include <xxhash.h>

#include <cstdlib>
#include <cstring>
#include <new>

#include "common/base/check.h"

namespace raystack::store {

uint64_t Checksum(std::span<const uint8_t> bytes) { return XXH3_64bits(bytes.data(), bytes.size()); }

void ShuffleBytes(const uint8_t* in, uint64_t size, uint8_t* out) {
  const uint64_t words = size / 4;
  for (uint64_t i = 0; i < words; ++i) {
    out[i] = in[4 * i];
    out[words + i] = in[4 * i + 1];
    out[2 * words + i] = in[4 * i + 2];
    out[3 * words + i] = in[4 * i + 3];
  }
  // The tail, if any (memcpy with a null pointer is undefined even for 0 bytes).
  if (size % 4 != 0) std::memcpy(out + 4 * words, in + 4 * words, size - 4 * words);
}

void UnshuffleBytes(const uint8_t* in, uint64_t size, uint8_t* out) {
  const uint64_t words = size / 4;
  for (uint64_t i = 0; i < words; ++i) {
    out[4 * i] = in[i];
    out[4 * i + 1] = in[words + i];
    out[4 * i + 2] = in[2 * words + i];
    out[4 * i + 3] = in[3 * words + i];
  }
  if (size % 4 != 0) std::memcpy(out + 4 * words, in + 4 * words, size - 4 * words);
}

void EncodeBlock(std::span<const uint8_t> raw, std::vector<uint8_t>* stored, bool shuffle) {
  CHECK(raw.size() < static_cast<size_t>(LZ4_MAX_INPUT_SIZE));
  const int raw_size = static_cast<int>(raw.size());
  std::vector<uint8_t> shuffled;
  const uint8_t* source = raw.data();
  if (shuffle) {
    shuffled.resize(raw.size());
    ShuffleBytes(raw.data(), raw.size(), shuffled.data());
    source = shuffled.data();
  }
  stored->resize(static_cast<size_t>(LZ4_compressBound(raw_size)));
  const int n = LZ4_compress_default(reinterpret_cast<const char*>(source),
                                     reinterpret_cast<char*>(stored->data()), raw_size,
                                     static_cast<int>(stored->size()));
  CHECK(n > 0);
  stored->resize(static_cast<size_t>(n));
}

uint64_t MaxStoredBytes(uint32_t raw_bytes) {
  const uint64_t n = raw_bytes;
  return n + n / 255 + 16;  // LZ4_COMPRESSBOUND, without its int range limit
}

void AlignedBuffer::Free::operator()(uint8_t* p) const {
  if (arena != nullptr) {
    arena->Free(p, bytes);
  } else {
    std::free(p);
  }
}

bool AlignedBuffer::ReserveIn(PopulatedArena* arena, uint64_t bytes) {
  CHECK(data_ == nullptr);
  uint8_t* p = arena->Allocate(bytes);
  if (p == nullptr) return false;
  data_ = std::unique_ptr<uint8_t, Free>(p, Free{arena, bytes});
  capacity_ = bytes;
  return true;
}

void AlignedBuffer::Reserve(uint64_t bytes) {
  if (bytes <= capacity_) return;
  const uint64_t rounded = (bytes + 63) & ~uint64_t{63};
  auto* p = static_cast<uint8_t*>(std::aligned_alloc(64, rounded));
  // Out of memory is the caller's to report (a block that cannot be decoded), not a crash.
  if (p == nullptr) throw std::bad_alloc();
  data_ = std::unique_ptr<uint8_t, Free>(p, Free{});  // a heap buffer's deleter, not an arena's
  capacity_ = rounded;
}

Status DecodeBlock(std::span<const uint8_t> stored, uint32_t raw_bytes, bool shuffled,
                   AlignedBuffer* scratch, AlignedBuffer* raw_out) {
  if (raw_bytes > static_cast<uint32_t>(LZ4_MAX_INPUT_SIZE) ||
      stored.size() > static_cast<size_t>(LZ4_MAX_INPUT_SIZE))
    return Status::Error("sizes out of range");
  // Every block has a header, so an index entry claiming 0 bytes is damage; decoding it would
  // also hand an unallocated buffer to the unshuffle (found by the block fuzzer).
  if (raw_bytes == 0) return Status::Error("raw size is 0");
  AlignedBuffer* target = shuffled ? scratch : raw_out;
  target->Reserve(raw_bytes);
  const int n = LZ4_decompress_safe(reinterpret_cast<const char*>(stored.data()),
                                    reinterpret_cast<char*>(target->data()),
                                    static_cast<int>(stored.size()), static_cast<int>(raw_bytes));
  if (n != static_cast<int>(raw_bytes)) return Status::Error("lz4 data is corrupt");
  if (!shuffled) return OkStatus();
  raw_out->Reserve(raw_bytes);
  UnshuffleBytes(scratch->data(), raw_bytes, raw_out->data());
  return OkStatus();
}

}  // namespace raystack::store
