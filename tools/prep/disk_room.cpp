#include "tools/prep/disk_room.h"

#include <sys/stat.h>
#include <sys/statvfs.h>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <optional>

#include "common/base/log.h"

namespace raystack::prep {
namespace {

struct Room {
  dev_t device;
  uint64_t free_bytes;
};

// The file system `path` is on (its nearest existing folder: the store may not exist yet).
std::optional<Room> RoomOf(std::filesystem::path path) {
  path = std::filesystem::absolute(path);
  for (;;) {
    struct stat st;
    struct statvfs vfs;
    if (stat(path.c_str(), &st) == 0 && statvfs(path.c_str(), &vfs) == 0)
      return Room{st.st_dev, static_cast<uint64_t>(vfs.f_bavail) * static_cast<uint64_t>(vfs.f_frsize)};
    if (!path.has_relative_path()) return std::nullopt;  // no check rather than a wrong one
    path = path.parent_path();
  }
}

double Gb(uint64_t bytes) { return static_cast<double>(bytes) / 1e9; }

}  // namespace

bool WarnIfDiskMayRunOut(const BuildDiskNeeds& needs, const std::string& temp_dir,
                         const std::string& store_dir, bool lower_bound) {
  const char* write = lower_bound ? "write at least" : "likely write about";
  const char* take = lower_bound ? "take at least" : "likely take about";
  const std::optional<Room> temp = RoomOf(temp_dir), store = RoomOf(store_dir);
  if (!temp || !store) return false;
  const uint64_t temp_peak = needs.spool_bytes + needs.temp_bytes;
  if (temp->device == store->device) {
    // The bucket files are deleted as the store is written (a persona's false alarm counted
    // both at once): the peak is the larger, beside the spool.
    const uint64_t peak = needs.spool_bytes + std::max(needs.temp_bytes, needs.store_bytes);
    if (peak <= temp->free_bytes) return false;
    LOG_WARNING("prep", "the build will %s %.2f GB of temporary files in %s and "
                "%.2f GB of store in %s, on one file system with %.2f GB free: it would fail when the disk fills; free space there, or give --temp-dir "
                "or -o on another disk", write, Gb(temp_peak), temp_dir.c_str(),
                Gb(needs.store_bytes), store_dir.c_str(), Gb(temp->free_bytes));
    return true;
  }
  bool warned = false;
  if (temp_peak > temp->free_bytes) {
    warned = true;
    LOG_WARNING("prep", "the build will %s %.2f GB of temporary files in %s, "
                "whose file system has %.2f GB free: it would fail when the disk fills; free space there, "
                "or give --temp-dir on a larger disk", write, Gb(temp_peak), temp_dir.c_str(),
                Gb(temp->free_bytes));
  }
  if (needs.store_bytes > store->free_bytes) {
    warned = true;
    LOG_WARNING("prep", "the store will %s %.2f GB in %s, whose file system has "
                "%.2f GB free: it would fail when the disk fills; free space there, or give -o on a larger "
                "disk", take, Gb(needs.store_bytes), store_dir.c_str(), Gb(store->free_bytes));
  }
  return warned;
}

}  // namespace raystack::prep
