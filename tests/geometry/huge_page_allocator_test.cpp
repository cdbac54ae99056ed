// HugePageAllocator (WideBvh's nodes and leaves): large arrays aligned to 2 MB and advised as
// huge-page candidates, small ones ordinary, both usable.

#include "common/base/huge_page_allocator.h"
#include "tests/support/resident_pages.h"

#include <gtest/gtest.h>
#include <sys/mman.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace raystack {
namespace {

struct alignas(64) Line {
  uint32_t value[16];
};

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
  const std::string flags = testing::VmFlagsOf(lines.data());
  ASSERT_FALSE(flags.empty()) << "no mapping in /proc/self/smaps holds the array";
  EXPECT_NE(flags.find(" hg"), std::string::npos) << flags;
  std::vector<Line, HugePageAllocator<Line>> small(3);
  EXPECT_EQ(testing::VmFlagsOf(small.data()).find(" hg"), std::string::npos);
}

}  // namespace
}  // namespace raystack
