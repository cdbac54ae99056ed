#pragma once
// This build's identity: the project's version and the git commit it was built from, e.g.
// "0.1.0 (c318adc1f2e4)"; with uncommitted changes "-dirty-" and a hash of them; "no git" when
// built from a source tarball. The ranks of one job must run the same build (two builds may
// render the same pixel differently: the master refuses a slave of another build), and a
// checkpoint written by another build is not resumed (it is part of the provenance).
//
// Written at every build by build_id.cmake, and only when it changes, so a build that changes
// nothing relinks nothing.

namespace raystack {

const char* BuildId();

}  // namespace raystack
