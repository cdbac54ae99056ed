#include "common/mpi/mpi_transport.h"

#include <mpi.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iterator>
#include <new>
#include <optional>
#include <thread>

#include "common/base/log.h"

namespace raystack::mpi {
namespace {

constexpr int kTag = 7;

std::string MpiError(int code) {
  char text[MPI_MAX_ERROR_STRING];
  int length = 0;
  MPI_Error_string(code, text, &length);
  return std::string(text, static_cast<size_t>(length));
}

}  // namespace

bool LaunchedByMpirun() {
  return std::getenv("OMPI_COMM_WORLD_SIZE") != nullptr || std::getenv("PMI_SIZE") != nullptr ||
         std::getenv("PMIX_RANK") != nullptr;
}

namespace {

transport::Transport::HostShare HostShareFromEnvironment(int rank) {
  transport::Transport::HostShare share{1, rank == 0};
  const auto number = [](const char* name) -> std::optional<int> {
    const char* text = std::getenv(name);
    if (text == nullptr) return std::nullopt;
    char* end = nullptr;
    const long value = std::strtol(text, &end, 10);
    if (end == text || *end != '\0' || value < 0 || value > (1 << 24)) return std::nullopt;
    return static_cast<int>(value);
  };
  const std::optional<int> local_size = number("OMPI_COMM_WORLD_LOCAL_SIZE");
  const std::optional<int> local_rank = number("OMPI_COMM_WORLD_LOCAL_RANK");
  if (!local_size || !local_rank || *local_size < 1) return share;
  share.ranks = *local_size;
  share.with_rank0 = number("OMPI_MCA_orte_num_nodes") == 1 || rank - *local_rank == 0;
  return share;
}

}  // namespace

Expected<std::unique_ptr<MpiTransport>> MpiTransport::Init(int* argc, char*** argv) {
  // Open MPI's shared-memory transport may copy a large message straight out of the
  // sender's memory (CMA); a sender killed in the middle leaves the receiver's transport
  // wedged, so a lost slave would hang the master. Copy through shared buffers instead
  // (unless the user chose otherwise).
  setenv("OMPI_MCA_btl_vader_single_copy_mechanism", "none", /*overwrite=*/0);
  // Oversubscribed (more ranks than cores, as on the emulated cluster), Open MPI makes every
  // progress call that finds nothing call sched_yield; Receive probes every sender between
  // its sleeps, so that was most of an idle rank's CPU (perf: the receiving thread took 40%
  // of a capped slave's time). Receive sleeps instead of spinning: no yield needed.
  setenv("OMPI_MCA_mpi_yield_when_idle", "0", /*overwrite=*/0);
  // Every rank on this one host: shared memory is the transport, and Open MPI's choice of a
  // messaging layer (trying the `cm` layer's network libraries first) took ~200 ms of
  // MPI_Init; the plain `ob1` layer starts in ~90 ms (a performance helper's measurement:
  // mpirun -np 3 of an 8x8 image, 0.45 -> 0.25 s). Across hosts Open MPI still chooses.
  const char* local = std::getenv("OMPI_COMM_WORLD_LOCAL_SIZE");
  const char* world = std::getenv("OMPI_COMM_WORLD_SIZE");
  if (local && world && std::strcmp(local, world) == 0)
    setenv("OMPI_MCA_pml", "ob1", /*overwrite=*/0);
  int provided = 0;
  if (const int rc = MPI_Init_thread(argc, argv, MPI_THREAD_MULTIPLE, &provided);
      rc != MPI_SUCCESS)
    return Status::Error("MPI_Init_thread failed: " + MpiError(rc));
  // Errors come back as codes (and become Status), instead of aborting the job in MPI.
  MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
  if (provided < MPI_THREAD_MULTIPLE) {
    MPI_Finalize();
    return Status::Error("this MPI library does not provide MPI_THREAD_MULTIPLE");
  }
  int rank = 0, size = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  return std::unique_ptr<MpiTransport>(new MpiTransport(rank, size, HostShareFromEnvironment(rank)));
}

struct MpiTransport::Incoming {
  bool active = false, too_large = false;
  int count = 0;
  MPI_Request request = MPI_REQUEST_NULL;
  std::vector<uint8_t> bytes;
};

MpiTransport::MpiTransport(int rank, int size, HostShare host_share)
    : rank_(rank),
      size_(size),
      host_share_(host_share),
      dead_(std::make_unique<std::atomic<bool>[]>(static_cast<size_t>(size))),
      incoming_(static_cast<size_t>(size)) {}

struct MpiTransport::Posted {
  int to = 0;
  MPI_Request request = MPI_REQUEST_NULL;
  std::vector<uint8_t> bytes;
};

MpiTransport::~MpiTransport() {
  // Posted answers still in flight are given a few seconds to be taken (MPI_Finalize with
  // sends pending is erroneous); a peer that stopped receiving does not hold the end up.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  for (;;) {
    {
      std::lock_guard lock(posted_mu_);
      (void)ProgressPosted();
      if (posted_.empty()) break;
      if (std::chrono::steady_clock::now() >= deadline) {
        for (Posted& p : posted_) {
          MPI_Request_free(&p.request);
          abandoned_.push_back(std::move(p.bytes));
        }
        posted_.clear();
        break;
      }
    }
    std::this_thread::sleep_for(std::chrono::microseconds(100));
  }
  MPI_Finalize();
}

Status MpiTransport::Send(int to, std::span<const uint8_t> bytes) {
  if (to < 0 || to >= size_) return Status::Error(StrFormat("rank %d: no rank %d", rank_, to));
  if (bytes.size() > transport::kMaxMessageBytes)
    return Status::Error(StrFormat("rank %d: message of %zu bytes is too large", rank_,
                                   bytes.size()));
  // Not MPI_Send: a large message waits for its receiver (rendezvous), and a receiver that
  // died never comes. So the send is watched, and given up once `to` is known dead and has
  // had kDeadRankGrace to take it: "dead" may be a verdict on a rank that was only silent
  // (the master's --lost-after), and a message it must still hear (its shutdown) that needs
  // a few progress calls to go out would otherwise be dropped at the first one.
  // Sent from a copy of its own: a send given up on may still be read by MPI (a large message
  // goes when its receiver asks for it, and a rank judged dead may only have stalled), after
  // the caller's buffer is gone. The copy is then kept to the end. (Sends are small and few:
  // requests, tiles, reports.)
  std::vector<uint8_t> owned(bytes.begin(), bytes.end());
  MPI_Request request;
  int rc = MPI_Isend(owned.data(), static_cast<int>(owned.size()), MPI_BYTE, to, kTag,
                     MPI_COMM_WORLD, &request);
  auto pause = std::chrono::microseconds(5);
  const auto began = std::chrono::steady_clock::now();
  for (int done = 0; rc == MPI_SUCCESS;) {
    rc = MPI_Test(&request, &done, MPI_STATUS_IGNORE);
    if (done) break;
    if (dead_[static_cast<size_t>(to)].load() &&
        std::chrono::steady_clock::now() - began >= kDeadRankGrace) {
      MPI_Request_free(&request);  // never completes; the process ends without MPI_Finalize
      {
        std::lock_guard posted_lock(posted_mu_);
        abandoned_.push_back(std::move(owned));
      }
      return Status::Error(StrFormat("rank %d: rank %d is gone, the message to it is dropped",
                                     rank_, to));
    }
    std::this_thread::sleep_for(pause);
    pause = std::min(pause * 2, std::chrono::microseconds(100));
  }
  if (rc != MPI_SUCCESS)
    return Status::Error(StrFormat("rank %d: sending to rank %d failed: %s", rank_, to,
                                   MpiError(rc).c_str()));
  return OkStatus();
}

Status MpiTransport::Post(int to, std::vector<uint8_t> bytes) {
  if (to < 0 || to >= size_) return Status::Error(StrFormat("rank %d: no rank %d", rank_, to));
  if (bytes.size() > transport::kMaxMessageBytes)
    return Status::Error(StrFormat("rank %d: message of %zu bytes is too large", rank_,
                                   bytes.size()));
  std::lock_guard lock(posted_mu_);
  if (dead_[static_cast<size_t>(to)].load())
    return Status::Error(StrFormat("rank %d: rank %d is gone, the message to it is dropped",
                                   rank_, to));
  // The node keeps its place in the list, so the buffer MPI reads stays where it is.
  Posted& p = posted_.emplace_back();
  p.to = to;
  p.bytes = std::move(bytes);
  if (const int rc = MPI_Isend(p.bytes.data(), static_cast<int>(p.bytes.size()), MPI_BYTE, to,
                               kTag, MPI_COMM_WORLD, &p.request);
      rc != MPI_SUCCESS) {
    posted_.pop_back();
    return Status::Error(StrFormat("rank %d: sending to rank %d failed: %s", rank_, to,
                                   MpiError(rc).c_str()));
  }
  posted_count_.store(posted_.size());
  return ProgressPosted();
}

Status MpiTransport::ProgressPosted() {
  // One MPI_Testsome for all of them: MPI_Test each would make one progress call per send in
  // flight, and an owner may have an answer in flight for every fetch its peers have out.
  std::vector<MPI_Request> requests;
  requests.reserve(posted_.size());
  for (const Posted& p : posted_) requests.push_back(p.request);
  std::vector<int> finished(requests.size());
  std::vector<MPI_Status> statuses(requests.size());
  int count = 0;
  if (!requests.empty()) {
    const int rc = MPI_Testsome(static_cast<int>(requests.size()), requests.data(), &count,
                                finished.data(), statuses.data());
    // MPI_ERR_IN_STATUS: the failed sends' own errors are in their statuses.
    for (int k = 0; rc == MPI_ERR_IN_STATUS && k < count && posted_error_.ok(); ++k) {
      const int err = statuses[static_cast<size_t>(k)].MPI_ERROR;
      if (err != MPI_SUCCESS)
        posted_error_ = Status::Error(StrFormat(
            "rank %d: a posted send to rank %d failed: %s", rank_,
            std::next(posted_.begin(), finished[static_cast<size_t>(k)])->to,
            MpiError(err).c_str()));
    }
    if (rc != MPI_SUCCESS && posted_error_.ok())
      posted_error_ = Status::Error(StrFormat("rank %d: a posted send failed: %s", rank_,
                                              MpiError(rc).c_str()));
  }
  size_t i = 0;
  uint64_t bytes = 0;
  for (auto it = posted_.begin(); it != posted_.end(); ++i) {
    if (requests[i] == MPI_REQUEST_NULL) {  // done (Testsome frees finished requests)
      it = posted_.erase(it);
    } else if (dead_[static_cast<size_t>(it->to)].load()) {  // never completes
      MPI_Request_free(&requests[i]);
      abandoned_.push_back(std::move(it->bytes));
      it = posted_.erase(it);
    } else {
      bytes += it->bytes.size();
      ++it;
    }
  }
  posted_count_.store(posted_.size());
  posted_bytes_.store(bytes);
  Status error = posted_error_;
  posted_error_ = OkStatus();
  return error;
}

void MpiTransport::NoteRankWillNotEnd(int rank) {
  NoteRankDied(rank);  // nothing waits for it either
  rank_will_not_end_ = true;
}

void MpiTransport::NoteRankDied(int rank) {
  rank_died_ = true;
  if (rank >= 0 && rank < size_) dead_[static_cast<size_t>(rank)] = true;
}

// A message is received with MPI_Irecv and watched, not MPI_Recv: a large message comes in
// fragments, and a sender that dies between two never completes it. A receive in progress
// stays with its sender (other senders' messages are taken meanwhile, that sender's later
// ones wait, so each sender's messages keep their order) until it completes, or until the
// sender is known dead (NoteRankDied), when it is dropped.
Expected<std::optional<transport::Envelope>> MpiTransport::Receive(
    std::chrono::milliseconds timeout) {
  // Failures are returned, never thrown: out of memory for a message (an address-space limit)
  // ended the receiving thread's process with std::terminate.
  try {
    return ReceiveOrThrow(timeout);
  } catch (const std::bad_alloc&) {
    return Status::Error(kOutOfMemory);  // nothing allocated here (status.h)
  }
}

Expected<std::optional<transport::Envelope>> MpiTransport::ReceiveOrThrow(
    std::chrono::milliseconds timeout) {
  std::lock_guard lock(receive_mu_);
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  // A rank with an idle pace (a slave, whose CPU is its rays') looks at kBusyPause while a
  // thread waits, from the look that BeginWait wakes it for: a look costs it more than the
  // latency it saves. A master looks at its quickest (from kFirstPause, doubling).
  const std::chrono::microseconds first_pause = idle_pause_us_.load() > 0 ? kBusyPause : kFirstPause;
  auto pause = first_pause;
  for (;;) {
    if (posted_count_.load() > 0) {  // the posted sends progress while this rank waits
      std::lock_guard posted_lock(posted_mu_);
      RAYSTACK_RETURN_IF_ERROR(ProgressPosted());
    }
    probes_.fetch_add(1, std::memory_order_relaxed);
    // One probe for any sender first: when nothing has come (most wake-ups) that is one
    // progress call instead of one per rank.
    bool any_active = false;
    for (const Incoming& in : incoming_) any_active = any_active || in.active;
    int anything = 0;
    if (!any_active) {
      if (const int rc = MPI_Iprobe(MPI_ANY_SOURCE, kTag, MPI_COMM_WORLD, &anything,
                                    MPI_STATUS_IGNORE);
          rc != MPI_SUCCESS)
        return Status::Error(StrFormat("rank %d: MPI_Iprobe failed: %s", rank_,
                                       MpiError(rc).c_str()));
    }
    for (int i = 0; i < size_ && (any_active || anything); ++i) {
      const int from = (next_source_ + i) % size_;
      Incoming& in = incoming_[static_cast<size_t>(from)];
      if (!in.active) {
        int flag = 0;
        MPI_Status status;
        if (const int rc = MPI_Iprobe(from, kTag, MPI_COMM_WORLD, &flag, &status); rc != MPI_SUCCESS)
          return Status::Error(StrFormat("rank %d: MPI_Iprobe failed: %s", rank_, MpiError(rc).c_str()));
        if (!flag) continue;
        int count = 0;
        MPI_Get_count(&status, MPI_BYTE, &count);
        // A message too large is still received (into one byte, truncated) so the queue
        // moves on; the caller gets an error naming the sender.
        in.too_large = count < 0 || static_cast<uint64_t>(count) > transport::kMaxMessageBytes;
        in.count = count;
        in.bytes.assign(in.too_large ? 1 : static_cast<size_t>(count), 0);
        if (const int rc = MPI_Irecv(in.bytes.data(), in.too_large ? 1 : count, MPI_BYTE, from,
                                     kTag, MPI_COMM_WORLD, &in.request);
            rc != MPI_SUCCESS)
          return Status::Error(StrFormat("rank %d: receiving from rank %d failed: %s", rank_,
                                         from, MpiError(rc).c_str()));
        in.active = true;
      }
      int done = 0;
      const int rc = MPI_Test(&in.request, &done, MPI_STATUS_IGNORE);
      if (!done && rc == MPI_SUCCESS) {
        if (dead_[static_cast<size_t>(from)].load()) {  // it will never come
          // Kept to the end: "dead" may be a verdict on a rank that only stalled, and MPI
          // would write the rest of its message here when it runs again. Kept before the
          // request is freed: if keeping it runs out of memory, the receive is still whole.
          std::lock_guard posted_lock(posted_mu_);
          abandoned_.push_back(std::move(in.bytes));
          in.active = false;
          MPI_Request_free(&in.request);
        }
        continue;
      }
      in.active = false;
      next_source_ = (from + 1) % size_;  // fairness: the next call starts after this sender
      if (in.too_large)
        return Status::Error(StrFormat("message from rank %d: %d bytes, more than the %llu a "
                                       "message may have", from, in.count,
                                       static_cast<unsigned long long>(transport::kMaxMessageBytes)));
      if (rc != MPI_SUCCESS)
        return Status::Error(StrFormat("rank %d: receiving from rank %d failed: %s", rank_,
                                       from, MpiError(rc).c_str()));
      transport::Envelope e;
      e.from = from;
      e.bytes = std::move(in.bytes);
      last_message_ = std::chrono::steady_clock::now();
      return std::optional<transport::Envelope>(std::move(e));
    }
    const auto now = std::chrono::steady_clock::now();
    if (now >= deadline) return std::optional<transport::Envelope>();
    const std::chrono::microseconds idle(idle_pause_us_.load());
    if (idle.count() > 0 && waiters_.load() == 0) {
      // Nothing on this rank waits for an answer: one look per idle pause, or at once when a
      // thread begins to wait.
      std::unique_lock wake_lock(wake_mu_);
      wake_.wait_for(wake_lock, std::min<std::chrono::steady_clock::duration>(idle, deadline - now),
                     [&] { return waiters_.load() > 0; });
      pause = first_pause;
      continue;
    }
    std::this_thread::sleep_for(pause);
    // While messages come (a peer's block requests, pixel batches) a sender waits little; once
    // none has come for a while, each wake-up costs more than the latency it saves (on a
    // capped node the receiving thread's wake-ups took a fifth of its CPU).
    const auto longest = now - last_message_ > kQuietAfter ? kQuietPause : kBusyPause;
    pause = std::min(pause * 2, longest);
  }
}

void MpiTransport::BeginWait() {
  if (waiters_.fetch_add(1) == 0) {
    std::lock_guard lock(wake_mu_);  // so a Receive between its check and its wait hears it
    wake_.notify_all();
  }
}

void MpiTransport::EndWait() { waiters_.fetch_sub(1); }

void MpiTransport::ExitWithoutFinalize(int code) {
  std::fflush(nullptr);
  std::_Exit(code);
}

void MpiTransport::Abort(int code) {
  MPI_Abort(MPI_COMM_WORLD, code);
  std::abort();
}

}  // namespace raystack::mpi
