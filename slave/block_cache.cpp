#include "slave/block_cache.h"

#include <algorithm>
#include <cmath>
#include <new>

#include "common/base/check.h"
#include "common/base/log.h"

namespace raystack::slave {
namespace {

// What a block costs the budget: its decoded bytes, 64-byte rounded (the memory it really uses).
uint64_t ChargeOf(const store::BlockEntry& e) {
  return (uint64_t{e.raw_bytes} + 63) & ~uint64_t{63};
}

// The arena's size: the budget and an eighth, or the whole store decoded when that is less
// (an in-core cache, or a budget above the store: then nothing is evicted and no gap forms).
uint64_t ArenaCapacity(const store::StoreReader& store, uint64_t budget) {
  uint64_t total = 0;
  for (const store::BlockEntry& e : store.blocks()) total += ChargeOf(e);
  return budget >= total ? total : std::min(total, budget + budget / 8);  // kUnlimited: no overflow
}

}  // namespace

Expected<std::unique_ptr<BlockCache>> BlockCache::Create(const store::StoreReader& store,
                                                         uint64_t budget_bytes) {
  uint64_t largest = 0;
  for (const store::BlockEntry& e : store.blocks())
    largest = std::max(largest, ChargeOf(e));
  if (budget_bytes < largest)
    return Status::Error(StrFormat(
        "cache budget of %llu bytes is smaller than the largest block of %s (%llu bytes); "
        "give --cache-mb at least %.2f",
        static_cast<unsigned long long>(budget_bytes), store.dir().c_str(),
        static_cast<unsigned long long>(largest),
        std::ceil(static_cast<double>(largest) * 100 / (1 << 20)) / 100));  // MiB, fractions too
  return std::unique_ptr<BlockCache>(new BlockCache(store, budget_bytes));
}

BlockCache::BlockCache(const store::StoreReader& store, uint64_t budget)
    : store_(store),
      budget_(budget),
      arena_(ArenaCapacity(store, budget)),
      entries_(store.blocks().size()) {}

uint64_t BlockCache::Charge(uint32_t id) const {
  return ChargeOf(store_.blocks()[id]);
}

const store::BlockView* BlockCache::TryAcquire(uint32_t id) {
  Entry& e = entries_[id];
  const int32_t before = e.pins.fetch_add(1, std::memory_order_acquire);
  if (before < 0 || e.state.load(std::memory_order_acquire) != kResidentState) {
    Release(id);
    return nullptr;
  }
  return &e.data->view;
}

const store::BlockView* BlockCache::ResidentView(uint32_t id) const {
  CHECK(budget_ == kUnlimited);  // a bounded cache may evict it at any time
  const Entry& e = entries_[id];
  return e.state.load(std::memory_order_acquire) == kResidentState ? &e.data->view : nullptr;
}

void BlockCache::Release(uint32_t id) {
  Entry& e = entries_[id];
  e.last_use.store(clock_.fetch_add(1, std::memory_order_relaxed), std::memory_order_relaxed);
  // seq_cst on both sides (here and in BeginLoad) so a loader about to wait for room either
  // sees this pin gone or is seen waiting and woken: no lost wake-up.
  const int32_t before = e.pins.fetch_sub(1);
  if (before == 1 && waiting_.load() > 0) {
    std::lock_guard lock(mu_);
    changed_.notify_all();
  }
}

bool BlockCache::MakeRoom(uint64_t need) {
  if (budget_ - used_ >= need) return true;
  // Evict a little more than needed (1/32 of the budget) so the scan is amortised over the
  // next few loads; the order stays least recently used first.
  const uint64_t target = std::min(budget_, need + budget_ / 32);
  std::vector<std::pair<uint64_t, uint32_t>> candidates;
  candidates.reserve(resident_.size());
  for (uint32_t id : resident_)
    if (entries_[id].pins.load() == 0)
      candidates.push_back({entries_[id].last_use.load(std::memory_order_relaxed), id});
  std::sort(candidates.begin(), candidates.end());
  for (const auto& [tick, id] : candidates) {
    if (budget_ - used_ >= target) break;
    Entry& e = entries_[id];
    int32_t expected = 0;
    if (!e.pins.compare_exchange_strong(expected, kEvicting, std::memory_order_acq_rel)) continue;
    e.state.store(kAbsent, std::memory_order_release);
    e.data.reset();
    // Concurrent TryAcquire calls added and removed their own +1s meanwhile; undo only ours.
    e.pins.fetch_sub(kEvicting, std::memory_order_release);
    const uint32_t index = e.resident_index;
    resident_[index] = resident_.back();
    entries_[resident_[index]].resident_index = index;
    resident_.pop_back();
    used_ -= Charge(id);
    evictions_.fetch_add(1, std::memory_order_relaxed);
  }
  return budget_ - used_ >= need;
}

BlockCache::Claim BlockCache::BeginLoad(uint32_t id, bool wait) {
  std::unique_lock lock(mu_);
  Entry& e = entries_[id];
  const uint64_t need = Charge(id);
  // The block's state is looked at again after every wait: two sync ray threads missing one
  // block in a full cache both waited for room, the first loaded it and traced through it, and
  // the second then claimed it again and freed the first one's data under its pin (found by
  // ThreadSanitizer; the budget also charged it twice).
  if (wait) ++waiting_;  // before looking, see Release
  struct Unwait {
    std::atomic<int>* waiting;
    ~Unwait() {
      if (waiting) --*waiting;
    }
  } unwait{wait ? &waiting_ : nullptr};
  for (;;) {
    switch (e.state.load(std::memory_order_acquire)) {
      case kResidentState: return Claim::kResident;
      case kLoadingState: return Claim::kLoading;
      case kFailedState: return Claim::kFailed;
      default: break;
    }
    if (shutdown_) return Claim::kFailed;
    if (MakeRoom(need)) break;
    if (!wait) return Claim::kNoRoom;
    changed_.wait(lock);
  }
  used_ += need;
  CHECK_LE(used_, budget_);
  uint64_t peak = peak_.load();
  while (used_ > peak && !peak_.compare_exchange_weak(peak, used_)) {
  }
  e.state.store(kLoadingState, std::memory_order_release);
  return Claim::kLoad;
}

Status BlockCache::FinishLoad(uint32_t id, std::span<const uint8_t> stored, int pins,
                              store::AlignedBuffer* scratch) {
  std::unique_ptr<Resident> data;
  Expected<store::BlockView> view = Status::Error("");
  try {
    data = std::make_unique<Resident>();
    data->raw.ReserveIn(&arena_, Charge(id));  // when no gap fits: the C heap, in Decode
    view = store_.Decode(id, stored, scratch, &data->raw);
  } catch (const std::bad_alloc&) {  // (an address-space limit): the block fails
    view = Status::Error(kOutOfMemory);  // nothing allocated here (status.h)
  }
  std::lock_guard lock(mu_);
  Entry& e = entries_[id];
  loads_.fetch_add(1, std::memory_order_relaxed);
  if (!view.ok()) {
    KeepFailure(id, view.status());
    used_ -= Charge(id);
    e.state.store(kFailedState, std::memory_order_release);
    changed_.notify_all();
    return view.status();
  }
  data->view = *view;
  CHECK(e.data == nullptr);  // one claim per load (BeginLoad): never a pinned block's data
  e.data = std::move(data);
  e.pins.fetch_add(pins, std::memory_order_relaxed);
  e.last_use.store(clock_.fetch_add(1, std::memory_order_relaxed), std::memory_order_relaxed);
  e.resident_index = static_cast<uint32_t>(resident_.size());
  resident_.push_back(id);
  if (e.counted_in != frame_) {
    e.counted_in = frame_;
    distinct_.fetch_add(1, std::memory_order_relaxed);
  }
  e.state.store(kResidentState, std::memory_order_release);
  changed_.notify_all();
  return OkStatus();
}

void BlockCache::Shutdown() {
  std::lock_guard lock(mu_);
  shutdown_ = true;
  changed_.notify_all();
}

void BlockCache::StartFrame() {
  std::lock_guard lock(mu_);
  ++frame_;
}

void BlockCache::Reopen() {
  std::lock_guard lock(mu_);
  shutdown_ = false;
}

void BlockCache::FailLoad(uint32_t id, const Status& why) {
  std::lock_guard lock(mu_);
  KeepFailure(id, why);
  used_ -= Charge(id);
  entries_[id].state.store(kFailedState, std::memory_order_release);
  changed_.notify_all();
}

BlockCache::Claim BlockCache::WaitWhileLoading(uint32_t id) {
  std::unique_lock lock(mu_);
  Entry& e = entries_[id];
  ++waiting_;
  changed_.wait(lock, [&] { return shutdown_ || e.state.load() != kLoadingState; });
  --waiting_;
  switch (e.state.load()) {
    case kResidentState: return Claim::kResident;
    case kFailedState: return Claim::kFailed;
    default: return Claim::kLoad;  // evicted again already: the caller starts over
  }
}

void BlockCache::KeepFailure(uint32_t id, const Status& why) {
  // Out of memory for the record itself: the block still fails (its state is set by the
  // caller), and FailureOf says it was not loaded. Thrown here, it left the block loading and
  // its askers waiting for good.
  try {
    failures_.emplace(id, why);
  } catch (const std::bad_alloc&) {
  }
}

Status BlockCache::FailureOf(uint32_t id) const {
  std::lock_guard lock(mu_);
  const auto it = failures_.find(id);
  if (it != failures_.end()) return it->second;
  return Status::Error(StrFormat("%s: block %u was not loaded (the render is stopping)",
                                 store_.dir().c_str(), id));
}

uint64_t BlockCache::used_bytes() const {
  std::lock_guard lock(mu_);
  return used_;
}

uint64_t BlockCache::resident_count() const {
  std::lock_guard lock(mu_);
  return resident_.size();
}

}  // namespace raystack::slave
