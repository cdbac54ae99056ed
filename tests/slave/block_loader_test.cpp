// The loader's threads do not preempt ray threads when they wake (SCHED_BATCH, see
// common/base/thread_policy.h): every block is delivered from a thread with that policy, by
// each way the loader reads (itself from the page cache, its I/O workers when reads wait,
// its AIO threads for direct reads), and the threads that ask keep their own policy.

#include <gtest/gtest.h>
#include <sched.h>

#include <atomic>
#include <chrono>
#include <map>
#include <mutex>
#include <string>
#include <thread>

#include "render_fixture.h"
#include "slave/block_cache.h"
#include "slave/block_loader.h"
#include "slave/block_source.h"

namespace raystack::testing {
namespace {

// Loads every block of `store` through a loader and returns how many were delivered from a
// thread under each scheduling policy.
std::map<int, int> DeliveringPolicies(const store::StoreReader& store, slave::FaultOptions faults) {
  auto cache = slave::BlockCache::Create(store, uint64_t{64} << 20);
  EXPECT_TRUE(cache.ok());
  if (!cache.ok()) return {};
  slave::DiskBlockSource disk(store, faults);
  std::mutex mu;
  std::map<int, int> policies;
  std::atomic<int> pending{0};
  slave::BlockCache* c = cache->get();
  {
    slave::BlockLoader loader(store, c, &disk, slave::LoaderOptions{},
                              [&](uint32_t, uint32_t block, const Status& st) {
                                EXPECT_TRUE(st.ok()) << st.message();
                                if (st.ok()) c->Release(block);  // the loader's pin
                                std::lock_guard lock(mu);
                                ++policies[sched_getscheduler(0)];
                                --pending;
                              });
    const auto count = static_cast<uint32_t>(store.blocks().size());
    for (uint32_t block = 0; block < count; block += 2) {  // every other: runs of one block
      ++pending;
      loader.Request(block, block % 4);
    }
    while (pending.load() > 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    EXPECT_EQ(loader.aio(), faults.io_latency_us == 0 && store.direct_reads());
    loader.Stop();
  }
  return policies;
}

TEST(BlockLoader, ItsThreadsDoNotPreemptTheThreadsThatAsk) {
  TestStore s = BuildGenerated("sphere:20000", 4);
  const std::unique_ptr<store::StoreReader> direct = OpenDirect(s);
  ASSERT_TRUE(direct);
  const auto blocks = static_cast<int>((s.reader->blocks().size() + 1) / 2);
  ASSERT_GE(blocks, 8);
  struct Case {
    const char* name;
    const store::StoreReader* store;
    uint32_t latency_us;
  };
  for (const Case& c : {Case{"page cache", s.reader.get(), 0}, Case{"1 ms a read", s.reader.get(), 1000},
                        Case{"direct reads (AIO)", direct.get(), 0}}) {
    SCOPED_TRACE(c.name);
    slave::FaultOptions faults;
    faults.io_latency_us = c.latency_us;
    const std::map<int, int> policies = DeliveringPolicies(*c.store, faults);
    EXPECT_EQ(policies.size(), 1u);
    EXPECT_EQ(policies.count(SCHED_BATCH) ? policies.at(SCHED_BATCH) : 0, blocks);
  }
  EXPECT_EQ(sched_getscheduler(0), SCHED_OTHER);  // the asking thread's own stays
}

}  // namespace
}  // namespace raystack::testing
