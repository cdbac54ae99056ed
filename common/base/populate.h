#pragma once
// Memory mapped in before it is written (madvise MADV_POPULATE_WRITE, Linux 5.14): one system
// call for a whole range instead of one page fault per 4 KB page. In a PVM guest each fault
// leaves the guest (~11 us a page), so a 960x540 film written a page at a time cost ~50 ms.
// Where the kernel lacks the call, the pages come one fault at a time as without it.
//
// Ordinary pages: memory new to a guest whose host takes freed memory back is mapped several
// times faster as 4 KB pages than as huge pages (tools/bench/RESULTS.md, "The block cache on
// 4 KB pages"); arrays written and read a row or a block at a time do not need the TLB's reach.

#include <sys/mman.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <limits>
#include <new>

namespace raystack {

#ifdef MADV_POPULATE_WRITE
inline constexpr int kMadvPopulateWrite = MADV_POPULATE_WRITE;
#else
inline constexpr int kMadvPopulateWrite = 23;  // Linux 5.14; older headers lack the name
#endif

// Arrays smaller than this come mostly from memory the heap already holds, and the many small
// ones (the converter's builds) should not pay a system call each.
inline constexpr size_t kPopulateAtLeast = size_t{1} << 20;

// Maps the whole pages of [p, p + bytes) in one call, for memory about to be written whole
// that some other allocator handed out (a std::vector's).
inline void PopulateForWrite(void* p, size_t bytes) {
  // The kernel's page: 4 KB on x86-64, 4, 16 or 64 KB on arm64 (madvise refuses a range that
  // does not start on one).
  static const auto page = static_cast<size_t>(sysconf(_SC_PAGESIZE));
  const auto begin = (reinterpret_cast<uintptr_t>(p) + page - 1) / page * page;
  const auto end = (reinterpret_cast<uintptr_t>(p) + bytes) / page * page;
  if (end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, kMadvPopulateWrite);
}

// Reserves room for n elements in `v` about to be filled to n or more (a BVH build's arrays
// over a whole model), mapped in one call when they take kPopulateAtLeast or more: written a
// page at a time, --mode bvh's build took ~40,000 faults for the dragon.
template <typename Vector>
void ReserveForWrite(Vector* v, size_t n) {
  v->reserve(n);
  const size_t bytes = n * sizeof(typename Vector::value_type);
  if (bytes >= kPopulateAtLeast) PopulateForWrite(v->data(), bytes);
}

// An allocator for arrays written whole as soon as they are made (a film): large ones are
// mapped in one call. Not for vectors reserved larger than they grow (a BVH being built): that
// would make memory of capacity never used.
template <typename T>
struct PopulatedAllocator {
  using value_type = T;

  PopulatedAllocator() = default;
  template <typename U>
  explicit PopulatedAllocator(const PopulatedAllocator<U>&) {}

  T* allocate(size_t n) {
    if (n > std::numeric_limits<size_t>::max() / sizeof(T)) throw std::bad_array_new_length();
    void* p = ::operator new(n * sizeof(T), std::align_val_t{alignof(T)});
    if (n * sizeof(T) >= kPopulateAtLeast) PopulateForWrite(p, n * sizeof(T));
    return static_cast<T*>(p);
  }
  void deallocate(T* p, size_t) { ::operator delete(p, std::align_val_t{alignof(T)}); }

  friend bool operator==(const PopulatedAllocator&, const PopulatedAllocator&) { return true; }
};

}  // namespace raystack
