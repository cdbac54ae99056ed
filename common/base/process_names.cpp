#include "common/base/process_names.h"

#include <signal.h>
#include <unistd.h>

#include <cerrno>

namespace raystack {

const std::string& HostName() {
  static const std::string name = [] {
    char buffer[256] = {};
    if (gethostname(buffer, sizeof buffer - 1) != 0 || buffer[0] == '\0') return std::string("host");
    std::string n(buffer);
    for (char& c : n)
      if (c == '/' || c == '\0') c = '_';
    return n;
  }();
  return name;
}

bool ProcessGone(long pid) {
  return pid > 0 && kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH;
}

}  // namespace raystack
