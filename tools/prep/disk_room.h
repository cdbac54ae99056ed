#pragma once
// Before the octree is built (hours on a model of billions of triangles), the disk it will write
// is checked against the free space where it goes: a full disk found at the end cost a user the
// whole run. A warning, since the needs are estimates (EstimateBuildDisk).

#include <string>

#include "tools/prep/octree_builder.h"

namespace raystack::prep {

// Warns when `needs` is more than the free space of the temporary folder's file system and the
// store's (on one file system, the spool and the larger of the bucket files and the store: the
// buckets are deleted as the store is written). `store_dir` need not exist yet. `lower_bound`:
// the needs are the least the build may write (an OBJ's size, before it is read), said so.
// Returns whether it warned.
bool WarnIfDiskMayRunOut(const BuildDiskNeeds& needs, const std::string& temp_dir,
                         const std::string& store_dir, bool lower_bound = false);

}  // namespace raystack::prep
