#pragma once
// The Transport over MPI (the only code of raystack that includes mpi.h). Every message is
// one MPI_Send of bytes with one tag on MPI_COMM_WORLD, so MPI keeps the order per pair of
// ranks. MPI is initialised with MPI_THREAD_MULTIPLE (OpenMPI 4.1 provides it), because a
// slave's ray threads send pixel batches while its receiver waits for tiles; Init refuses to
// run with less.
//
// Receive probes for any sender and sleeps between probes (MPI has no wait-with-timeout): at
// most 500 us while messages come, so a peer's block request waits little, and up to 1 ms
// once none has come for 2 ms, so an idle rank spends little CPU on wake-ups. With an idle
// pause (SetIdlePause, a slave's), it sleeps that long between probes while no thread waits
// for an answer, and a BeginWait wakes it at once. A message larger than kMaxMessageBytes is
// an error naming its sender (it is still drained, so the next one can be read).

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <list>
#include <memory>
#include <mutex>
#include <vector>

#include "common/transport/transport.h"

namespace raystack::mpi {

// True when this process was started by mpirun / mpiexec (OpenMPI or MPICH environment), so
// a front end can decide whether to initialise MPI at all.
bool LaunchedByMpirun();

class MpiTransport final : public transport::Transport {
 public:
  // MPI_Init_thread; one per process. The destructor calls MPI_Finalize.
  static Expected<std::unique_ptr<MpiTransport>> Init(int* argc, char*** argv);
  ~MpiTransport() override;

  int rank() const override { return rank_; }
  int size() const override { return size_; }
  // From Open MPI's environment, not a collective call (MPI_Comm_split_type at Init): a rank of
  // an older build, which makes no such call, left the others waiting in it, so the job hung
  // before the master could name the other build. OMPI_COMM_WORLD_LOCAL_SIZE ranks here; rank 0
  // among them on a one-node job, or where this node's ranks start at 0 (ranks placed by slot,
  // mpirun's default). Elsewhere (srun, MPICH): this rank alone.
  HostShare host_share() const override { return host_share_; }
  Status Send(int to, std::span<const uint8_t> bytes) override;
  // MPI_Isend of bytes it keeps; Receive (and the next Post) test the sends in flight and drop
  // the finished ones, and those to a rank known dead.
  Status Post(int to, std::vector<uint8_t> bytes) override;
  Expected<std::optional<transport::Envelope>> Receive(std::chrono::milliseconds timeout) override;
  // Receive, but out of memory is thrown (Receive turns it into an error).
  Expected<std::optional<transport::Envelope>> ReceiveOrThrow(std::chrono::milliseconds timeout);
  uint64_t posted_bytes() const override { return posted_bytes_.load(); }
  void SetIdlePause(std::chrono::microseconds pause) override { idle_pause_us_ = pause.count(); }
  void BeginWait() override;
  void EndWait() override;
  // Looks for messages Receive has taken so far (what waiting costs, for tests and benches).
  uint64_t probes() const { return probes_.load(); }
  // Ends every rank of the job (MPI_Abort), for errors that one rank cannot recover from.
  [[noreturn]] void Abort(int code);
  void NoteRankDied(int rank) override;
  // Then the process must end without MPI_Finalize (ExitWithoutFinalize), which would wait
  // for the dead rank; mpirun --enable-recovery accepts that.
  bool rank_died() const { return rank_died_.load(); }
  // Whether rank `rank` in particular was noted dead.
  bool dead(int rank) const override {
    return rank >= 0 && rank < size_ && dead_[static_cast<size_t>(rank)].load();
  }
  void NoteRankWillNotEnd(int rank) override;
  // Then the job must end by force (Abort): mpirun would wait for that rank, under
  // --enable-recovery forever.
  bool rank_will_not_end() const { return rank_will_not_end_.load(); }
  [[noreturn]] static void ExitWithoutFinalize(int code);

 private:
  MpiTransport(int rank, int size, HostShare host_share);
  int rank_, size_;
  HostShare host_share_;
  std::atomic<bool> rank_died_{false}, rank_will_not_end_{false};
  std::unique_ptr<std::atomic<bool>[]> dead_;  // by rank
  // Receives in progress, by sender (Receive; defined where mpi.h is).
  struct Incoming;
  // Posted sends in flight (defined where mpi.h is).
  struct Posted;
  // Tests the posted sends, drops the finished ones; the first failure. Holds posted_mu_.
  Status ProgressPosted();
  std::mutex posted_mu_;
  std::list<Posted> posted_;
  std::list<std::vector<uint8_t>> abandoned_;  // given up on (dead ranks): MPI may still use them
  std::atomic<size_t> posted_count_{0};
  std::atomic<uint64_t> posted_bytes_{0};
  Status posted_error_;
  std::mutex receive_mu_;
  std::vector<Incoming> incoming_;
  // Receive's longest sleep between probes: kBusyPause, or kQuietPause once no message has
  // come for kQuietAfter. (kBusyPause was 100 us: with --blocks rem's requests batched, a
  // capped slave's receiving thread woke ~10^4 times a second for little; 500 us measured
  // faster in interleaved runs, tools/bench/RESULTS.md.)
  static constexpr std::chrono::microseconds kFirstPause{20}, kBusyPause{500}, kQuietPause{1000};
  static constexpr std::chrono::milliseconds kQuietAfter{2};
  // How long Send still tries to reach a rank known dead (see Send).
  static constexpr std::chrono::milliseconds kDeadRankGrace{200};
  std::chrono::steady_clock::time_point last_message_{};
  std::atomic<int64_t> idle_pause_us_{0};
  std::atomic<int> waiters_{0};  // threads between BeginWait and EndWait
  std::atomic<uint64_t> probes_{0};
  std::mutex wake_mu_;           // Receive sleeps on wake_ until a BeginWait
  std::condition_variable wake_;
  int next_source_ = 0;
};

}  // namespace raystack::mpi
