// Memory mapped in before it is written (common/base/populate.h): PopulatedAllocator (a film),
// PopulateForWrite (another allocator's memory), ReserveForWrite (a BVH build's arrays).

#include "common/base/populate.h"
#include "tests/support/resident_pages.h"

#include <gtest/gtest.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cstdint>
#include <memory>
#include <vector>

namespace raystack {
namespace {

constexpr size_t kMB = size_t{1} << 20;

// The kernel's page (4 KB on x86-64; 16 or 64 KB on some arm64 kernels), as PopulateForWrite uses.
size_t PageBytes() { return static_cast<size_t>(sysconf(_SC_PAGESIZE)); }

struct alignas(64) Line {
  uint32_t value[16];
};

// A film: the pages are in memory as soon as the array is allocated, before its first write;
// from the plain heap they come as they are first written. Small arrays are not populated.
TEST(PopulatedAllocator, LargeArraysAreInMemoryBeforeTheFirstWrite) {
  if (!testing::KernelPopulatesOnRequest())
    GTEST_SKIP() << "this kernel cannot map pages in on request (MADV_POPULATE_WRITE, Linux 5.14)";
  // 64 MB: above glibc's largest mmap threshold, so each array is a fresh mapping, never
  // memory an earlier test touched.
  const size_t n = 64 * kMB / sizeof(Line);
  std::allocator<Line> lazy;
  Line* q = lazy.allocate(n);
  EXPECT_LT(testing::ResidentShare(q, n * sizeof(Line)), 0.5);
  lazy.deallocate(q, n);
  PopulatedAllocator<Line> populated;
  Line* p = populated.allocate(n);
  EXPECT_EQ(reinterpret_cast<uintptr_t>(p) % alignof(Line), 0u);
  // The whole pages of the array (its first and last may share a page with the heap's own).
  const size_t page = PageBytes();
  EXPECT_EQ(testing::ResidentShare(reinterpret_cast<char*>(p) + page, n * sizeof(Line) - 2 * page),
            1.0);
  p[n - 1].value[15] = 3;
  EXPECT_EQ(p[n - 1].value[15], 3u);
  populated.deallocate(p, n);
  std::vector<Line, PopulatedAllocator<Line>> small(3);
  small[2].value[0] = 1;
  EXPECT_EQ(small[2].value[0], 1u);
}

// The whole pages inside the range are in memory after it, before any write; the pages it only
// partly covers are left alone.
TEST(PopulateForWrite, MapsTheWholePagesOfARange) {
  if (!testing::KernelPopulatesOnRequest())
    GTEST_SKIP() << "this kernel cannot map pages in on request (MADV_POPULATE_WRITE, Linux 5.14)";
  const size_t page = PageBytes(), pages = 64;
  void* mapped = mmap(nullptr, pages * page, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS,
                      -1, 0);
  ASSERT_NE(mapped, MAP_FAILED);
  char* base = static_cast<char*>(mapped);
  EXPECT_EQ(testing::ResidentShare(base, pages * page), 0.0);
  // From the middle of page 1 to the middle of page 61: pages 2-60 are whole inside it.
  PopulateForWrite(base + page + page / 2, 60 * page);
  EXPECT_EQ(testing::ResidentShare(base + 2 * page, 59 * page), 1.0);
  EXPECT_EQ(testing::ResidentShare(base, 2 * page), 0.0);
  EXPECT_EQ(testing::ResidentShare(base + 61 * page, 3 * page), 0.0);
  munmap(mapped, pages * page);
}

// Room for n, the size unchanged, and a large array's whole pages in memory before any write.
TEST(ReserveForWrite, MapsALargeVectorBeforeItIsFilled) {
  if (!testing::KernelPopulatesOnRequest())
    GTEST_SKIP() << "this kernel cannot map pages in on request (MADV_POPULATE_WRITE, Linux 5.14)";
  std::vector<char> large;
  ReserveForWrite(&large, 6 * kMB);
  EXPECT_EQ(large.size(), 0u);
  ASSERT_GE(large.capacity(), 6 * kMB);
  const size_t page = PageBytes();
  const auto first = (reinterpret_cast<uintptr_t>(large.data()) + page - 1) / page * page;
  EXPECT_EQ(testing::ResidentShare(reinterpret_cast<const void*>(first), 4 * kMB), 1.0);
  std::vector<char> small;
  ReserveForWrite(&small, 100);
  EXPECT_GE(small.capacity(), 100u);
}

}  // namespace
}  // namespace raystack
