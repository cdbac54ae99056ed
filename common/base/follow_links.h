#pragma once
// The file a path names, through any symbolic links (relative ones from their own folder), the
// last one dangling or not: what a tool writes when given a link, so that the file it names is
// written and the link stays (a link given as an output was replaced by the file written, its
// target left as it was: a hostile-input review).

#include <string>

namespace raystack {

std::string FollowLinks(const std::string& path);

}  // namespace raystack
