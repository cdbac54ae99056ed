#include "common/base/memory_available.h"

#include <sys/resource.h>

#include <algorithm>
#include <fstream>
#include <sstream>

namespace raystack {
namespace {

std::optional<uint64_t> ReadNumber(const std::string& file) {
  std::ifstream in(file);
  std::string word;
  if (!(in >> word) || word.empty() || word.find_first_not_of("0123456789") != std::string::npos)
    return std::nullopt;  // missing, unreadable, or "max"
  try {
    return std::stoull(word);
  } catch (...) {
    return std::nullopt;
  }
}

std::string ReadAll(const std::string& file) {
  std::ifstream in(file);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// cgroup v1 says "no limit" with the largest page-aligned 63-bit value; anything beyond a
// petabyte is no limit in practice.
constexpr uint64_t kNoLimit = uint64_t{1} << 50;

// The value in bytes of a "Key:   1234 kB" line of /proc's text (meminfo, status).
std::optional<uint64_t> KilobytesFieldIn(const std::string& text, const std::string& key) {
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind(key, 0) != 0) continue;
    std::istringstream fields(line.substr(key.size()));
    uint64_t kb = 0;
    std::string unit;
    if (fields >> kb >> unit && unit == "kB") return kb * 1024;
    return std::nullopt;
  }
  return std::nullopt;
}

}  // namespace

std::optional<uint64_t> MemAvailableIn(const std::string& meminfo) {
  return KilobytesFieldIn(meminfo, "MemAvailable:");
}

std::optional<uint64_t> CgroupRoom(const std::string& cgroup_fs, const std::string& path,
                                   const char* limit_file, const char* usage_file) {
  std::optional<uint64_t> room;
  std::string group = path;
  for (;;) {
    const std::string dir = cgroup_fs + (group == "/" ? "" : group) + "/";
    const std::optional<uint64_t> limit = ReadNumber(dir + limit_file);
    const std::optional<uint64_t> usage = ReadNumber(dir + usage_file);
    if (limit && usage && *limit < kNoLimit) {
      const uint64_t here = *limit > *usage ? *limit - *usage : 0;
      room = room ? std::min(*room, here) : here;
    }
    if (group.empty() || group == "/") break;
    const size_t slash = group.find_last_of('/');
    group = slash == 0 || slash == std::string::npos ? "/" : group.substr(0, slash);
  }
  return room;
}

MemoryCgroups MemoryCgroupsIn(const std::string& proc_cgroup) {
  MemoryCgroups groups;
  std::istringstream lines(proc_cgroup);
  std::string line;
  while (std::getline(lines, line)) {
    const size_t a = line.find(':'), b = a == std::string::npos ? a : line.find(':', a + 1);
    if (b == std::string::npos) continue;
    const std::string controllers = line.substr(a + 1, b - a - 1), path = line.substr(b + 1);
    std::istringstream list(controllers);
    for (std::string c; std::getline(list, c, ',');)
      if (c == "memory") groups.v1 = path;
    if (controllers.empty() && line.rfind("0:", 0) == 0) groups.v2 = path;
  }
  return groups;
}

MemoryCgroups OwnMemoryCgroups() { return MemoryCgroupsIn(ReadAll("/proc/self/cgroup")); }

uint64_t AddressSpaceRoom(uint64_t limit, uint64_t vm_size) {
  return vm_size >= limit ? 0 : limit - vm_size;
}

std::optional<uint64_t> VmSizeIn(const std::string& proc_status) {
  return KilobytesFieldIn(proc_status, "VmSize:");
}

std::optional<uint64_t> MemoryThisProcessMayTake(uint64_t reserve) {
  std::optional<uint64_t> room = MemoryAvailable();
  rlimit limit{};
  if (getrlimit(RLIMIT_AS, &limit) != 0 || limit.rlim_cur == RLIM_INFINITY) return room;
  const std::optional<uint64_t> vm = VmSizeIn(ReadAll("/proc/self/status"));
  if (!vm) return room;
  // kRenderReserve: what a render reserves beyond its data as it runs, thread stacks, malloc's
  // per-thread arenas, decode buffers (an mpirun slave under 330 MB passed the check on its
  // blocks alone and ran out at once; under 400 MB it rendered: ~100 MB more, on 2 ray threads
  // and the loader's). More threads reserve more: the check is a floor, not a promise.
  const uint64_t free_space = AddressSpaceRoom(limit.rlim_cur, *vm);
  const uint64_t under_limit = free_space > reserve ? free_space - reserve : 0;
  return room ? std::min(*room, under_limit) : under_limit;
}

std::optional<uint64_t> MemoryAvailable() {
  std::optional<uint64_t> available = MemAvailableIn(ReadAll("/proc/meminfo"));
  const auto take = [&](std::optional<uint64_t> room) {
    if (room) available = available ? std::min(*available, *room) : *room;
  };
  const MemoryCgroups groups = OwnMemoryCgroups();
  if (groups.v1)
    take(CgroupRoom(kCgroupV1Memory, *groups.v1, "memory.limit_in_bytes", "memory.usage_in_bytes"));
  if (groups.v2) take(CgroupRoom(kCgroupV2, *groups.v2, "memory.max", "memory.current"));
  return available;
}

uint64_t PeakRssBytes() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmHWM:", 0) == 0) return std::stoull(line.substr(6)) * 1024;
  return 0;
}

}  // namespace raystack
