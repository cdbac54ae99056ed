#pragma once
// A real binary running in the background while a test looks at it (the preview is served
// while `raystack render` runs): output to files, waits for a line, SIGTERM, the exit code.

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "tests/prep/run_process.h"

namespace raystack::master::preview::testing {

class BackgroundProcess {
 public:
  BackgroundProcess(const std::vector<std::string>& argv, const std::string& scratch_dir)
      : out_(scratch_dir + "/bg-stdout.txt"), err_(scratch_dir + "/bg-stderr.txt") {
    std::vector<char*> args;
    for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    pid_ = fork();
    if (pid_ == 0) {
      const int out = open(out_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      const int err = open(err_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (out < 0 || err < 0 || dup2(out, 1) < 0 || dup2(err, 2) < 0) _exit(126);
      setpgid(0, 0);  // its own group, so that a test that fails can end it and its children
      execv(args[0], args.data());
      _exit(127);
    }
  }
  BackgroundProcess(const BackgroundProcess&) = delete;
  BackgroundProcess& operator=(const BackgroundProcess&) = delete;
  ~BackgroundProcess() {
    if (pid_ > 0 && !exited_) {
      kill(-pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
  }

  std::string out() const { return prep::testing::Slurp(out_); }
  std::string err() const { return prep::testing::Slurp(err_); }

  // Waits until stdout holds `text` (true) or the process ended or `timeout` passed (false).
  bool WaitForOutput(const std::string& text, std::chrono::seconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      if (out().find(text) != std::string::npos) return true;
      if (Exited()) return out().find(text) != std::string::npos;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return false;
  }
  // The line of stdout starting with `prefix`, without it ("" if none).
  std::string LineAfter(const std::string& prefix) const {
    const std::string text = out();
    const size_t at = text.find(prefix);
    if (at == std::string::npos) return "";
    const size_t end = text.find('\n', at);
    return text.substr(at + prefix.size(), end == std::string::npos ? std::string::npos : end - at - prefix.size());
  }

  void Signal(int sig) {
    if (pid_ > 0 && !exited_) kill(pid_, sig);
  }
  // Under mpirun: sends `sig` to the child of this process that is MPI rank `rank` (found by
  // its OMPI_COMM_WORLD_RANK); false if there is none.
  bool SignalRank(int rank, int sig) const {
    const std::string want = "OMPI_COMM_WORLD_RANK=" + std::to_string(rank);
    for (const auto& entry : std::filesystem::directory_iterator("/proc")) {
      const std::string name = entry.path().filename();
      if (name.find_first_not_of("0123456789") != std::string::npos) continue;
      std::ifstream stat(entry.path() / "stat");
      std::string line;
      std::getline(stat, line);
      const size_t close = line.rfind(')');  // "pid (comm) state ppid ..."
      if (close == std::string::npos) continue;
      std::istringstream rest(line.substr(close + 1));
      std::string state;
      pid_t ppid = 0;
      rest >> state >> ppid;
      if (ppid != pid_) continue;
      std::ifstream environ(entry.path() / "environ", std::ios::binary);
      for (std::string var; std::getline(environ, var, '\0');) {
        if (var == want) return kill(static_cast<pid_t>(std::stoi(name)), sig) == 0;
      }
    }
    return false;
  }
  // Waits for the end; the exit code, or -1 if it was killed by a signal.
  int Wait() {
    if (!exited_) {
      waitpid(pid_, &status_, 0);
      exited_ = true;
    }
    return WIFEXITED(status_) ? WEXITSTATUS(status_) : -1;
  }
  // Whether it has ended (without waiting).
  bool Exited() {
    if (!exited_ && waitpid(pid_, &status_, WNOHANG) == pid_) exited_ = true;
    return exited_;
  }

 private:
  std::string out_, err_;
  pid_t pid_ = -1;
  int status_ = 0;
  bool exited_ = false;
};

}  // namespace raystack::master::preview::testing
