#pragma once
// An allocator for large arrays walked in no particular order (a BVH over a whole model):
// allocations of kHugePage bytes or more are aligned to kHugePage and advised to the kernel as
// huge-page candidates (madvise MADV_HUGEPAGE) before they are first touched, so one TLB entry
// covers 2 MB of them instead of 4 KB. Debian's kernels enable transparent huge pages in
// "madvise" mode: without the advice, a walk through the dragon's 78 MB tree misses the TLB on
// most node and leaf loads (Embree advises its trees the same way). Smaller arrays, and systems
// without transparent huge pages (the advice then fails and is ignored), get ordinary pages.
// Arrays written whole as soon as they are made take PopulatedAllocator (populate.h) instead.

#include <sys/mman.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <new>

namespace raystack {

inline constexpr size_t kHugePage = size_t{2} << 20;

template <typename T>
struct HugePageAllocator {
  using value_type = T;
  template <typename U>
  struct rebind {
    using other = HugePageAllocator<U>;
  };

  HugePageAllocator() = default;
  template <typename U>
  explicit HugePageAllocator(const HugePageAllocator<U>&) {}

  T* allocate(size_t n) {
    if (n > std::numeric_limits<size_t>::max() / sizeof(T)) throw std::bad_array_new_length();
    const size_t bytes = n * sizeof(T);
    if (bytes < kHugePage)
      return static_cast<T*>(::operator new(bytes, std::align_val_t{alignof(T)}));
    const size_t rounded = Rounded(bytes);
    void* p = std::aligned_alloc(kHugePage, rounded);
    if (p == nullptr) throw std::bad_alloc();
    madvise(p, rounded, MADV_HUGEPAGE);  // a hint: where it fails, ordinary pages
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
