#pragma once
// A real headless Chromium (Debian's /usr/bin/chromium) driven over the DevTools protocol on
// --remote-debugging-pipe (JSON messages ending in NUL on fds 3 and 4): opens a page and
// evaluates JavaScript in it, which is how the browser tests read the preview's canvas back.
// Debian packages only: no node, no driver.

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

namespace raystack::master::preview::testing {

class HeadlessChromium {
 public:
  static constexpr const char* kBinary = "/usr/bin/chromium";
  static bool Installed() { return access(kBinary, X_OK) == 0; }

  HeadlessChromium() = default;
  HeadlessChromium(const HeadlessChromium&) = delete;
  HeadlessChromium& operator=(const HeadlessChromium&) = delete;
  ~HeadlessChromium() { Quit(); }

  // Starts the browser with a new, empty profile in `profile_dir` (its log goes there too).
  bool Start(const std::string& profile_dir, std::string* error) {
    int to_browser[2], from_browser[2];
    if (pipe(to_browser) != 0 || pipe(from_browser) != 0) return Fail(error, "pipe failed");
    const std::string log = profile_dir + "/chromium.log";
    const std::vector<std::string> argv = {
        kBinary, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        // Without these three, Chromium's connections are refused on a closed network.
        "--disable-background-networking", "--disable-component-update", "--disable-sync",
        // Containers often have a small /dev/shm.
        "--disable-dev-shm-usage", "--user-data-dir=" + profile_dir, "--remote-debugging-pipe",
        "about:blank"};
    pid_ = fork();
    if (pid_ < 0) return Fail(error, "fork failed");
    if (pid_ == 0) {
      // The pipe ends move above 4 first, so that dup2 onto 3 and 4 cannot clobber them.
      const int in = fcntl(to_browser[0], F_DUPFD, 10), out = fcntl(from_browser[1], F_DUPFD, 10);
      const int log_fd = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (in < 0 || out < 0 || log_fd < 0 || dup2(in, 3) < 0 || dup2(out, 4) < 0 ||
          dup2(log_fd, 1) < 0 || dup2(log_fd, 2) < 0)
        _exit(126);
      for (int fd = 5; fd < 1024; ++fd) close(fd);
      std::vector<char*> args;
      for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
      args.push_back(nullptr);
      execv(kBinary, args.data());
      _exit(127);
    }
    close(to_browser[0]);
    close(from_browser[1]);
    to_ = to_browser[1];
    from_ = from_browser[0];
    signal(SIGPIPE, SIG_IGN);  // a browser that died shows as a failed write, not a killed test
    nlohmann::json version = Call("Browser.getVersion", nlohmann::json::object(), false, error);
    return !version.is_null();
  }

  // Opens `url` in a new tab; later Evaluate calls run in it.
  bool Open(const std::string& url, std::string* error) {
    const nlohmann::json target = Call("Target.createTarget", {{"url", url}}, false, error);
    if (target.is_null()) return false;
    const nlohmann::json attached = Call(
        "Target.attachToTarget", {{"targetId", target["targetId"]}, {"flatten", true}}, false, error);
    if (attached.is_null()) return false;
    session_ = attached["sessionId"].get<std::string>();
    return true;
  }

  // The value of a JavaScript expression in the page (null with `error` set if it threw).
  nlohmann::json Evaluate(const std::string& expression, std::string* error) {
    const nlohmann::json r = Call("Runtime.evaluate",
                                  {{"expression", expression}, {"returnByValue", true}}, true, error);
    if (r.is_null()) return r;
    if (r.contains("exceptionDetails")) {
      Fail(error, "the page threw: " + r["exceptionDetails"].dump());
      return nullptr;
    }
    return r["result"].value("value", nlohmann::json());
  }

  // Evaluates `expression` until it is true; false at `timeout` (a safety net against a hang,
  // not a measurement: the tests never assert how long anything took).
  bool WaitFor(const std::string& expression, std::chrono::seconds timeout, std::string* error) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      const nlohmann::json v = Evaluate(expression, error);
      if (v.is_boolean() && v.get<bool>()) return true;
      if (!error->empty()) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    return Fail(error, "timed out waiting for: " + expression);
  }

  void Quit() {
    if (pid_ <= 0) return;
    std::string ignored;
    if (to_ >= 0) Send("Browser.close", nlohmann::json::object(), false);
    if (to_ >= 0) close(to_);
    if (from_ >= 0) close(from_);
    to_ = from_ = -1;
    for (int i = 0; i < 100; ++i) {  // up to 5 s for a clean exit, then the hard way
      if (waitpid(pid_, nullptr, WNOHANG) == pid_) {
        pid_ = -1;
        return;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    kill(pid_, SIGKILL);
    waitpid(pid_, nullptr, 0);
    pid_ = -1;
  }

 private:
  static bool Fail(std::string* error, const std::string& why) {
    *error = why;
    return false;
  }

  int Send(const std::string& method, const nlohmann::json& params, bool in_session) {
    nlohmann::json m = {{"id", next_id_}, {"method", method}, {"params", params}};
    if (in_session) m["sessionId"] = session_;
    const std::string text = m.dump() + '\0';
    size_t sent = 0;
    while (sent < text.size()) {
      const ssize_t n = write(to_, text.data() + sent, text.size() - sent);
      if (n <= 0) return -1;
      sent += static_cast<size_t>(n);
    }
    return next_id_++;
  }

  // Sends a command and returns its "result" (events in between are skipped), or null.
  nlohmann::json Call(const std::string& method, const nlohmann::json& params, bool in_session,
                      std::string* error) {
    const int id = Send(method, params, in_session);
    if (id < 0) {
      Fail(error, "the browser is gone (writing " + method + ")");
      return nullptr;
    }
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (std::chrono::steady_clock::now() < deadline) {
      const size_t end = pending_.find('\0');
      if (end != std::string::npos) {
        const nlohmann::json m = nlohmann::json::parse(pending_.substr(0, end), nullptr, false);
        pending_.erase(0, end + 1);
        if (m.is_discarded() || !m.contains("id") || m["id"] != id) continue;
        if (m.contains("error")) {
          Fail(error, method + ": " + m["error"].dump());
          return nullptr;
        }
        return m.value("result", nlohmann::json::object());
      }
      pollfd p{from_, POLLIN, 0};
      if (poll(&p, 1, 1000) <= 0) continue;
      char buffer[65536];
      const ssize_t n = read(from_, buffer, sizeof buffer);
      if (n <= 0) {
        Fail(error, "the browser closed its pipe (during " + method + ")");
        return nullptr;
      }
      pending_.append(buffer, static_cast<size_t>(n));
    }
    Fail(error, "no answer to " + method);
    return nullptr;
  }

  pid_t pid_ = -1;
  int to_ = -1, from_ = -1;
  int next_id_ = 1;
  std::string session_, pending_;
};

// Base64 (as the page's preview.pixels() gives it) to bytes.
inline std::vector<uint8_t> DecodeBase64(const std::string& text) {
  std::vector<uint8_t> out;
  uint32_t bits = 0;
  int count = 0;
  for (char c : text) {
    int v;
    if (c >= 'A' && c <= 'Z') v = c - 'A';
    else if (c >= 'a' && c <= 'z') v = c - 'a' + 26;
    else if (c >= '0' && c <= '9') v = c - '0' + 52;
    else if (c == '+') v = 62;
    else if (c == '/') v = 63;
    else continue;  // '=' padding
    bits = (bits << 6) | static_cast<uint32_t>(v);
    count += 6;
    if (count >= 8) {
      count -= 8;
      out.push_back(static_cast<uint8_t>(bits >> count));
    }
  }
  return out;
}

}  // namespace raystack::master::preview::testing
