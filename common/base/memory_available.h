#pragma once
// How much more memory this process may fill, page cache included, before the kernel has to
// reclaim some: the machine's MemAvailable, or less where a cgroup memory limit on this
// process (or on a group above it) is nearer. cgroup v1 and v2. Linux; nullopt when nothing
// could be read.

#include <cstdint>
#include <optional>
#include <string>

namespace raystack {

std::optional<uint64_t> MemoryAvailable();

// Peak resident set size of this process since it started its program (VmHWM), 0 if unknown.
// Not getrusage's ru_maxrss, which Linux carries across exec from the process that forked it: a
// prep started by a 100 MB test binary reported "peak RSS 100 MiB" of a 32 MiB run.
uint64_t PeakRssBytes();

// What this process may still allocate: MemoryAvailable(), or less under an address-space limit
// (RLIMIT_AS: `ulimit -v`, some batch schedulers' memory limit, e.g. SGE's h_vmem), which
// counts address space reserved, not memory used: the room left under it, less `reserve`. For the checks before a render or a prep, not
// for the page cache (which no such limit bounds).
// `reserve`: what the process will reserve as it runs beyond the data it is checking for (a
// render's threads: kRenderReserve; the converter's budget counts its own).
inline constexpr uint64_t kRenderReserve = uint64_t{96} << 20;
std::optional<uint64_t> MemoryThisProcessMayTake(uint64_t reserve = kRenderReserve);
// The parts, for tests: the room under an address-space limit of `limit` bytes for a process
// of `vm_size` bytes (0 once at or over it).
uint64_t AddressSpaceRoom(uint64_t limit, uint64_t vm_size);
// VmSize in bytes from /proc/<pid>/status's text.
std::optional<uint64_t> VmSizeIn(const std::string& proc_status);

// Where a process sits in the hierarchies that can limit its memory: v1's memory controller
// (mounted at kCgroupV1Memory) and the unified v2 one (at kCgroupV2).
struct MemoryCgroups {
  std::optional<std::string> v1;  // e.g. "/a/b"
  std::optional<std::string> v2;
};
inline constexpr const char* kCgroupV1Memory = "/sys/fs/cgroup/memory";
inline constexpr const char* kCgroupV2 = "/sys/fs/cgroup";
// From /proc/<pid>/cgroup's text: "id:controllers:path" lines, v2's being "0::path".
MemoryCgroups MemoryCgroupsIn(const std::string& proc_cgroup);
MemoryCgroups OwnMemoryCgroups();

// The parts, for tests. MemAvailable in bytes from /proc/meminfo's text.
std::optional<uint64_t> MemAvailableIn(const std::string& meminfo);
// Room under the limits of a cgroup and its ancestors: the least of limit - usage (0 when a
// group is at or over its limit), nullopt when none has a limit. `cgroup_fs` is where the
// hierarchy is mounted (e.g. /sys/fs/cgroup/memory for v1), `path` the group's path in it
// ("/a/b", from /proc/self/cgroup); `limit_file` and `usage_file` are the names of the
// hierarchy's version (memory.limit_in_bytes and memory.usage_in_bytes, or memory.max and
// memory.current). A limit of "max" or absurdly large means none.
std::optional<uint64_t> CgroupRoom(const std::string& cgroup_fs, const std::string& path,
                                   const char* limit_file, const char* usage_file);

}  // namespace raystack
