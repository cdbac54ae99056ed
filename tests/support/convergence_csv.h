#pragma once
// Reads a convergence log (raystack render --convergence-log) for the tests: every row, its
// empty fields as NaN. A malformed row fails the calling test.

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

namespace raystack::testing {

struct LogRow {
  uint32_t frame = 0, pass = 0, min_samples = 0;
  std::string event;
  double seconds = 0;
  uint64_t rays = 0, samples = 0, pixels_covered = 0;
  double error_estimate = 0, rel_error_estimate = 0, rmse = 0, relmse = 0;
};

inline std::vector<LogRow> ReadConvergenceLog(const std::string& path) {
  std::vector<LogRow> rows;
  std::ifstream in(path);
  std::string line;
  EXPECT_TRUE(std::getline(in, line)) << path << ": empty";
  EXPECT_EQ(line, "frame,event,pass,seconds,rays,samples,pixels_covered,min_samples,"
                  "error_estimate,rel_error_estimate,rmse,relmse");
  while (std::getline(in, line)) {
    std::vector<std::string> f;
    std::stringstream ss(line);
    std::string cell;
    while (std::getline(ss, cell, ',')) f.push_back(cell);
    if (!line.empty() && line.back() == ',') f.push_back("");
    EXPECT_EQ(f.size(), 12u) << line;
    if (f.size() != 12) break;
    auto real = [](const std::string& s) {
      return s.empty() ? std::numeric_limits<double>::quiet_NaN() : std::stod(s);
    };
    LogRow r;
    r.frame = static_cast<uint32_t>(std::stoul(f[0]));
    r.event = f[1];
    r.pass = static_cast<uint32_t>(std::stoul(f[2]));
    r.seconds = std::stod(f[3]);
    r.rays = std::stoull(f[4]);
    r.samples = std::stoull(f[5]);
    r.pixels_covered = std::stoull(f[6]);
    r.min_samples = static_cast<uint32_t>(std::stoul(f[7]));
    r.error_estimate = real(f[8]);
    r.rel_error_estimate = real(f[9]);
    r.rmse = real(f[10]);
    r.relmse = real(f[11]);
    rows.push_back(r);
  }
  return rows;
}

}  // namespace raystack::testing
