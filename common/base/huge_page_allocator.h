#pragma once
// An allocator for large arrays walked in no particular order (a BVH over a whole model):
// allocations of kHugePage bytes or more are aligned to kHugePage and advised to the kernel as
// huge-page candidates (madvise MADV_HUGEPAGE) before they are first touched, so one TLB entry
// covers 2 MB of them instead of 4 KB. Debian's kernels enable transparent huge pages in
// "madvise" mode: without the advice, a walk through the dragon's 78 MB tree misses the TLB on
// most node and leaf loads (Embree advises its trees the same way). Smaller arrays, and systems
// without transparent huge pages (the advice then fails and is ignored), get ordinary pages.
//
// kPopulate: for arrays written whole as soon as they are made (a film), the pages are also
// mapped in one call before the first write (MADV_POPULATE_WRITE, Linux 5.14), instead of one
// fault per page: in a PVM guest each fault leaves the guest (~11 us a 4 KB page; a 960x540
// film is 55 MB). Not for vectors reserved larger than they grow (a BVH being built): that
// would make memory of capacity never used.

#include <sys/mman.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <new>

namespace raystack {

inline constexpr size_t kHugePage = size_t{2} << 20;
#ifdef MADV_POPULATE_WRITE
inline constexpr int kMadvPopulateWrite = MADV_POPULATE_WRITE;
#else
inline constexpr int kMadvPopulateWrite = 23;  // Linux 5.14; older headers lack the name
#endif

// Maps the whole pages of [p, p + bytes) in one call (MADV_POPULATE_WRITE), for memory about to
// be written whole: the same as kPopulate below for memory some other allocator handed out (a
// std::vector's). Where the kernel lacks it, the pages come one fault at a time as without it.
inline void PopulateForWrite(void* p, size_t bytes) {
  const size_t page = 4096;
  const auto begin = (reinterpret_cast<uintptr_t>(p) + page - 1) / page * page;
  const auto end = (reinterpret_cast<uintptr_t>(p) + bytes) / page * page;
  if (end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, kMadvPopulateWrite);
}

// Reserves room for n elements in `v` about to be filled to n or more (a BVH build's arrays
// over a whole model), mapped in one call (PopulateForWrite) when they take 1 MB or more:
// written a page at a time, --mode bvh's build took ~40,000 faults for the dragon. Smaller
// arrays mostly come from memory the heap already holds, and the many small builds of the
// converter should not pay a system call each.
template <typename Vector>
void ReserveForWrite(Vector* v, size_t n) {
  v->reserve(n);
  const size_t bytes = n * sizeof(typename Vector::value_type);
  if (bytes >= (size_t{1} << 20)) PopulateForWrite(v->data(), bytes);
}

template <typename T, bool kPopulate = false>
struct HugePageAllocator {
  using value_type = T;
  template <typename U>
  struct rebind {
    using other = HugePageAllocator<U, kPopulate>;
  };

  HugePageAllocator() = default;
  template <typename U>
  explicit HugePageAllocator(const HugePageAllocator<U, kPopulate>&) {}

  T* allocate(size_t n) {
    if (n > std::numeric_limits<size_t>::max() / sizeof(T)) throw std::bad_array_new_length();
    const size_t bytes = n * sizeof(T);
    if (bytes < kHugePage)
      return static_cast<T*>(::operator new(bytes, std::align_val_t{alignof(T)}));
    const size_t rounded = Rounded(bytes);
    void* p = std::aligned_alloc(kHugePage, rounded);
    if (p == nullptr) throw std::bad_alloc();
    madvise(p, rounded, MADV_HUGEPAGE);  // a hint: where it fails, ordinary pages
    // Where it fails (an older kernel), pages come one fault at a time as without it.
    if constexpr (kPopulate) madvise(p, rounded, kMadvPopulateWrite);
    return static_cast<T*>(p);
  }

  void deallocate(T* p, size_t n) {
    if (n * sizeof(T) < kHugePage) {
      ::operator delete(p, std::align_val_t{alignof(T)});
    } else {
      std::free(p);
    }
  }

  friend bool operator==(const HugePageAllocator&, const HugePageAllocator&) { return true; }

 private:
  static size_t Rounded(size_t bytes) { return (bytes + kHugePage - 1) / kHugePage * kHugePage; }
};

}  // namespace raystack
