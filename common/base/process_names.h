#pragma once
// Names that say which process made a file, so that a later run can tell the leftovers of a
// killed process (removable) from the files of a live one: this machine's name (a process id
// means something on its own host only, and a folder may be shared by several machines) and
// whether a process id of this machine is gone.

#include <string>

namespace raystack {

// gethostname(), with '/' replaced so that it can be part of a file name; "host" if unknown.
const std::string& HostName();

// True when no process `pid` runs on this machine (kill(pid, 0) says ESRCH); false when it
// runs, or when that cannot be told (no permission: not ours to judge).
bool ProcessGone(long pid);

}  // namespace raystack
