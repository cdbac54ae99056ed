// HugePageAllocator (WideBvh's nodes and leaves): large arrays aligned to 2 MB and advised as
// huge-page candidates, small ones ordinary, both usable.

#include "common/base/huge_page_allocator.h"
#include "tests/support/resident_pages.h"

#include <gtest/gtest.h>
#include <sys/mman.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace raystack {
namespace {

struct alignas(64) Line {
  uint32_t value[16];
};

// The VmFlags of the mapping that holds `p` in /proc/self/smaps ("" if none is found).
std::string VmFlagsOf(const void* p) {
  const auto address = reinterpret_cast<uintptr_t>(p);
  std::ifstream smaps("/proc/self/smaps");
  std::string line;
  bool inside = false;
  while (std::getline(smaps, line)) {
    uintptr_t begin = 0, end = 0;
    char dash = 0;
    std::istringstream range(line);
    if (range >> std::hex >> begin >> dash >> end && dash == '-') {
      inside = begin <= address && address < end;
    } else if (inside && line.rfind("VmFlags:", 0) == 0) {
      return line;
    }
  }
  return "";
}

TEST(HugePageAllocator, LargeArraysAreAlignedToHugePagesAndUsable) {
  std::vector<Line, HugePageAllocator<Line>> lines(3 * kHugePage / sizeof(Line));
  ASSERT_EQ(reinterpret_cast<uintptr_t>(lines.data()) % kHugePage, 0u);
  for (size_t i = 0; i < lines.size(); ++i) lines[i].value[i % 16] = static_cast<uint32_t>(i);
  for (size_t i = 0; i < lines.size(); i += 4097) EXPECT_EQ(lines[i].value[i % 16], i);
  lines.resize(lines.size() * 2);  // reallocates: the old block is freed as it was allocated
  EXPECT_EQ(reinterpret_cast<uintptr_t>(lines.data()) % kHugePage, 0u);
  EXPECT_EQ(lines[4097].value[4097 % 16], 4097u);
}

TEST(HugePageAllocator, SmallArraysKeepTheirTypesAlignment) {
  std::vector<Line, HugePageAllocator<Line>> lines(3);
  EXPECT_EQ(reinterpret_cast<uintptr_t>(lines.data()) % alignof(Line), 0u);
  lines[2].value[15] = 7;
  EXPECT_EQ(lines[2].value[15], 7u);
}

// Where the kernel has transparent huge pages, the large array's mapping carries the advice
// ("hg" in its VmFlags): the walks then get 2 MB pages where the kernel can give them.
TEST(HugePageAllocator, LargeArraysAreAdvisedAsHugePages) {
  if (!std::filesystem::exists("/sys/kernel/mm/transparent_hugepage/enabled"))
    GTEST_SKIP() << "this kernel has no transparent huge pages";
  std::vector<Line, HugePageAllocator<Line>> lines(3 * kHugePage / sizeof(Line));
  const std::string flags = VmFlagsOf(lines.data());
  ASSERT_FALSE(flags.empty()) << "no mapping in /proc/self/smaps holds the array";
  EXPECT_NE(flags.find(" hg"), std::string::npos) << flags;
  std::vector<Line, HugePageAllocator<Line>> small(3);
  EXPECT_EQ(VmFlagsOf(small.data()).find(" hg"), std::string::npos);
}

// kPopulate (a film): the pages are in memory as soon as the array is allocated, before its
// first write; without it they come as they are first written.
TEST(HugePageAllocator, PopulatedArraysAreInMemoryBeforeTheFirstWrite) {
  if (!testing::KernelPopulatesOnRequest())
    GTEST_SKIP() << "this kernel cannot map pages in on request (MADV_POPULATE_WRITE, Linux 5.14)";
  // 64 MB: above glibc's largest mmap threshold, so each array is a fresh mapping, never
  // memory an earlier test touched.
  const size_t n = 32 * kHugePage / sizeof(Line);
  HugePageAllocator<Line> lazy;
  Line* q = lazy.allocate(n);
  EXPECT_LT(testing::ResidentShare(q, n * sizeof(Line)), 0.5);
  lazy.deallocate(q, n);
  HugePageAllocator<Line, true> populated;
  Line* p = populated.allocate(n);
  EXPECT_EQ(testing::ResidentShare(p, n * sizeof(Line)), 1.0);
  populated.deallocate(p, n);
}

// PopulateForWrite (another allocator's memory, such as a resolved image's layers): the whole
// pages inside the range are in memory after it, before any write; the pages it only partly
// covers are left alone.
TEST(HugePageAllocator, PopulateForWriteMapsTheWholePagesOfARange) {
  if (!testing::KernelPopulatesOnRequest())
    GTEST_SKIP() << "this kernel cannot map pages in on request (MADV_POPULATE_WRITE, Linux 5.14)";
  const size_t page = 4096, pages = 64;
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

// ReserveForWrite (a BVH build's arrays over a whole model): room for n, the size unchanged,
// and a large array's whole pages in memory before any write.
TEST(HugePageAllocator, ReserveForWriteMapsALargeVectorBeforeItIsFilled) {
  if (!testing::KernelPopulatesOnRequest())
    GTEST_SKIP() << "this kernel cannot map pages in on request (MADV_POPULATE_WRITE, Linux 5.14)";
  std::vector<char> large;
  ReserveForWrite(&large, 3 * kHugePage);
  EXPECT_EQ(large.size(), 0u);
  ASSERT_GE(large.capacity(), 3 * kHugePage);
  const size_t page = 4096;
  const auto first = (reinterpret_cast<uintptr_t>(large.data()) + page - 1) / page * page;
  EXPECT_EQ(testing::ResidentShare(reinterpret_cast<const void*>(first), 2 * kHugePage), 1.0);
  std::vector<char> small;
  ReserveForWrite(&small, 100);
  EXPECT_GE(small.capacity(), 100u);
}

}  // namespace
}  // namespace raystack
