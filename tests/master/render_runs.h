#pragma once
// `raystack render` as the master's command-line tests run it: one process (np 0), or under a
// real mpirun with np ranks (1 master, np - 1 slaves), in `dir`.

#include <string>
#include <vector>

#include "tests/prep/run_process.h"
#include "tests/support/store_dir_fixture.h"

namespace raystack::testing {

inline prep::testing::ProcessResult RunRender(const std::string& dir, int np,
                                              const std::vector<std::string>& args) {
  std::vector<std::string> argv;
  if (np > 0)
    argv = {RAYSTACK_MPIRUN, "--allow-run-as-root", "--oversubscribe", "-np", std::to_string(np)};
  argv.push_back(kRaystackBinary);
  argv.push_back("render");
  argv.insert(argv.end(), args.begin(), args.end());
  return prep::testing::RunProcess(argv, dir);
}

}  // namespace raystack::testing
