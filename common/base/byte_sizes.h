#pragma once
// Sizes as the user reads them beside --cache-mb, which counts MiB: every size the render prints
// next to it in the same unit and precision (a user did not know "536.9 MB" for the 512 given,
// and "0.1 MiB of 0.0699997 MiB" read as a budget exceeded).

#include <cstdint>
#include <string>

#include "common/base/log.h"  // StrFormat

namespace raystack {

// `bytes` in MiB with three significant digits ("0.07", "25.2", "512"), whole from 999.5 on
// (where three digits would print "1e+03").
inline std::string MiB(uint64_t bytes) {
  const double v = static_cast<double>(bytes) / (1024.0 * 1024.0);
  return v >= 999.5 ? StrFormat("%.0f MiB", v) : StrFormat("%.3g MiB", v);
}

}  // namespace raystack
