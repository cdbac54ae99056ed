#pragma once
// The words for an option a command does not know, shared by raystack, raystack-prep and
// raystack-info: "--spp=1" is the GNU habit, and a new user read "unknown option --spp=1"
// without seeing that the value goes after a space here.

#include <string>

namespace raystack {

inline std::string UnknownOption(const std::string& arg) {
  const size_t equals = arg.find('=');
  if (arg.rfind("--", 0) == 0 && equals != std::string::npos && equals > 2)
    return "unknown option " + arg + " (no option takes '=': an option's value, if it takes one, "
           "follows it after a space; see --help)";
  return "unknown option " + arg + " (see --help)";
}

}  // namespace raystack
