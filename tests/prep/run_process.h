#pragma once
// Runs one of the real binaries the way a user would, capturing its output to files, for the
// command-line tests. `before_exec` runs in the child after fork (e.g. to join a cgroup).
// A run that outlives its deadline is killed with everything it started (its process group:
// mpirun and its ranks) and says so in its stderr, so a hang fails its test with the output so
// far instead of holding ctest to its timeout with nothing to show; where the machine has gdb,
// the stacks of every thread of the group come first, so a rare hang shows where it hung.

#include <fcntl.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
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

// The processes of process group `group`, with their command lines.
inline std::vector<std::pair<pid_t, std::string>> GroupMembers(pid_t group) {
  std::vector<std::pair<pid_t, std::string>> members;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator("/proc", ec)) {
    const std::string name = entry.path().filename().string();
    if (name.find_first_not_of("0123456789") != std::string::npos) continue;
    const std::string stat = Slurp(entry.path().string() + "/stat");
    const size_t close = stat.rfind(')');
    if (close == std::string::npos) continue;
    std::istringstream fields(stat.substr(close + 2));  // state, ppid, pgrp, ...
    std::string state;
    long ppid = 0, pgrp = 0;
    if (!(fields >> state >> ppid >> pgrp) || pgrp != group || state == "Z") continue;
    std::string cmdline = Slurp(entry.path().string() + "/cmdline");
    for (char& c : cmdline)
      if (c == '\0') c = ' ';
    members.emplace_back(static_cast<pid_t>(std::stol(name)), cmdline.substr(0, 200));
  }
  return members;
}

// Every thread's stack in every process of `group`, from gdb (attached for a moment), or ""
// where the machine has no gdb. Only the frame lines: enough to see where each thread waits.
inline std::string Backtraces(pid_t group, const std::string& scratch_dir) {
  if (access("/usr/bin/gdb", X_OK) != 0) return "";
  std::string text;
  for (const auto& [pid, cmdline] : GroupMembers(group)) {
    const std::string file = scratch_dir + "/backtrace-" + std::to_string(pid) + ".txt";
    const std::string command = "timeout 60 /usr/bin/gdb -p " + std::to_string(pid) +
                                " -batch -ex 'thread apply all bt 16' > " + file + " 2>&1";
    if (std::system(command.c_str()) != 0) continue;
    text += "== process " + std::to_string(pid) + ": " + cmdline + "\n";
    std::istringstream lines(Slurp(file));
    for (std::string line; std::getline(lines, line);)
      if (line.rfind("Thread ", 0) == 0 || line.rfind("#", 0) == 0) text += line + "\n";
  }
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
  std::string backtraces;  // of a run past its deadline
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::seconds(deadline_seconds);
  for (;;) {
    const pid_t done = waitpid(pid, &status, WNOHANG);
    if (done == pid) break;
    if (done < 0 && errno != EINTR) return result;
    if (std::chrono::steady_clock::now() > deadline && !result.timed_out) {
      result.timed_out = true;
      backtraces = Backtraces(pid, scratch_dir);
      kill(-pid, SIGKILL);  // the group: mpirun and its ranks
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  if (WIFEXITED(status)) result.exit_code = WEXITSTATUS(status);
  if (WIFSIGNALED(status)) result.signal = WTERMSIG(status);
  result.out = Slurp(out_path);
  result.err = Slurp(err_path);
  if (result.timed_out) {
    result.err += "\n[run_process] killed after " + std::to_string(deadline_seconds) +
                  " s, with its process group\n";
    if (!backtraces.empty()) result.err += "[run_process] its threads then:\n" + backtraces;
  }
  return result;
}

}  // namespace raystack::prep::testing
