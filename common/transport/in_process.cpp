#include "common/base/check.h"
#include "common/base/log.h"
#include "common/transport/transport.h"

namespace raystack::transport {

class InProcessTransport final : public Transport {
 public:
  InProcessTransport(InProcessHub* hub, int rank) : hub_(hub), rank_(rank) {}
  int rank() const override { return rank_; }
  int size() const override { return hub_->ranks(); }
  // Every rank is a thread of this process.
  HostShare host_share() const override { return {size(), true}; }

  Status Send(int to, std::span<const uint8_t> bytes) override {
    if (to < 0 || to >= size())
      return Status::Error(StrFormat("rank %d: no rank %d to send to", rank_, to));
    if (bytes.size() > kMaxMessageBytes)
      return Status::Error(StrFormat("rank %d: message of %zu bytes is too large", rank_,
                                     bytes.size()));
    InProcessHub::Mailbox& box = *hub_->boxes_[static_cast<size_t>(to)];
    {
      std::lock_guard lock(box.mu);
      box.queue.push_back({rank_, std::vector<uint8_t>(bytes.begin(), bytes.end())});
    }
    box.cv.notify_one();
    return OkStatus();
  }

  Expected<std::optional<Envelope>> Receive(std::chrono::milliseconds timeout) override {
    InProcessHub::Mailbox& box = *hub_->boxes_[static_cast<size_t>(rank_)];
    std::unique_lock lock(box.mu);
    if (!box.cv.wait_for(lock, timeout, [&] { return !box.queue.empty(); }))
      return std::optional<Envelope>();
    Envelope e = std::move(box.queue.front());
    box.queue.pop_front();
    return std::optional<Envelope>(std::move(e));
  }

 private:
  InProcessHub* hub_;
  int rank_;
};

InProcessHub::InProcessHub(int ranks) {
  CHECK(ranks >= 1);
  for (int i = 0; i < ranks; ++i) boxes_.push_back(std::make_unique<Mailbox>());
}

std::unique_ptr<Transport> InProcessHub::Endpoint(int rank) {
  CHECK(rank >= 0 && rank < ranks());
  return std::make_unique<InProcessTransport>(this, rank);
}

}  // namespace raystack::transport
