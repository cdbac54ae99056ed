#pragma once
// Runs one of the real binaries the way a user would, capturing its output to files, for the
// command-line tests. `before_exec` runs in the child after fork (e.g. to join a cgroup).
// A run that outlives its deadline is killed with everything it started (its process group:
// mpirun and its ranks) and says so in its stderr, so a hang fails its test with the output so
// far instead of holding ctest to its timeout with nothing to show.

#include <fcntl.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <functional>
#include <string>
#include <thread>
#include <vector>

namespace raystack::prep::testing {

inline const std::string kPrepBinary = RAYSTACK_BINARY_DIR "/tools/prep/raystack-prep";
inline const std::string kInfoBinary = RAYSTACK_BINARY_DIR "/tools/info/raystack-info";

struct ProcessResult {
  int exit_code = -1;  // -1 when it did not exit normally
  int signal = 0;      // the signal that ended it, if any
  bool timed_out = false;
  std::string out, err;
};

inline constexpr int kProcessDeadlineSeconds = 300;

// The whole file ("" if it cannot be read).
inline std::string Slurp(const std::string& path) {
  std::string text;
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return text;
  char buffer[1 << 16];
  size_t n;
  while ((n = std::fread(buffer, 1, sizeof buffer, f)) > 0) text.append(buffer, n);
  std::fclose(f);
  return text;
}

// Runs `argv` (argv[0] is the binary's path) with stdout and stderr going to files under
// `scratch_dir`, waits and returns what happened.
inline ProcessResult RunProcess(const std::vector<std::string>& argv, const std::string& scratch_dir,
                                const std::function<void()>& before_exec = {},
                                int deadline_seconds = kProcessDeadlineSeconds) {
  const std::string out_path = scratch_dir + "/stdout.txt", err_path = scratch_dir + "/stderr.txt";
  std::vector<char*> args;
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  ProcessResult result;
  const pid_t pid = fork();
  if (pid < 0) return result;
  if (pid == 0) {
    setpgid(0, 0);  // its own group, so a deadline can end all it started
    if (before_exec) before_exec();
    const int out = open(out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int err = open(err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (out < 0 || err < 0 || dup2(out, 1) < 0 || dup2(err, 2) < 0) _exit(126);
    execv(args[0], args.data());
    _exit(127);
  }
  int status = 0;
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::seconds(deadline_seconds);
  for (;;) {
    const pid_t done = waitpid(pid, &status, WNOHANG);
    if (done == pid) break;
    if (done < 0 && errno != EINTR) return result;
    if (std::chrono::steady_clock::now() > deadline && !result.timed_out) {
      result.timed_out = true;
      kill(-pid, SIGKILL);  // the group: mpirun and its ranks
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  if (WIFEXITED(status)) result.exit_code = WEXITSTATUS(status);
  if (WIFSIGNALED(status)) result.signal = WTERMSIG(status);
  result.out = Slurp(out_path);
  result.err = Slurp(err_path);
  if (result.timed_out)
    result.err += "\n[run_process] killed after " + std::to_string(deadline_seconds) +
                  " s, with its process group\n";
  return result;
}

}  // namespace raystack::prep::testing
