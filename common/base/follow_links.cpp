#include "common/base/follow_links.h"

#include <filesystem>
#include <system_error>

namespace raystack {

std::string FollowLinks(const std::string& given) {
  namespace fs = std::filesystem;
  fs::path p = given;
  std::error_code ec;
  for (int hops = 0; hops < 40 && fs::is_symlink(fs::symlink_status(p, ec)); ++hops) {
    const fs::path to = fs::read_symlink(p, ec);
    if (ec) break;
    p = to.is_absolute() ? to : p.parent_path() / to;
  }
  return p.string();
}

}  // namespace raystack
