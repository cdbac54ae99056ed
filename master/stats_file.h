#pragma once
// --stats: a JSON array of one record per frame, each written as its frame ends. After every
// record the file is a whole JSON array, so a run that fails, is interrupted or is killed keeps
// the figures of the frames it finished, and no frame's record is held in memory (the file was
// written once, at the end: a run of 10,000 frames kept them all, and a crash lost them all).

#include <cstdint>
#include <string>

#include "common/base/status.h"

namespace raystack::master {

class StatsFile {
 public:
  // Nothing is written with an empty `path`; the file is created (truncated) at the first
  // record, so a run that fails before any frame ends leaves an earlier file as it was.
  explicit StatsFile(std::string path) : path_(std::move(path)) {}
  ~StatsFile();
  StatsFile(const StatsFile&) = delete;
  StatsFile& operator=(const StatsFile&) = delete;

  // Adds `record` (a JSON object) at the end of the array. A failed write is said once, as a
  // warning; the run goes on (its images matter more) and Finish returns the error.
  void Append(const std::string& record);
  // The first write error, naming the file; OK if every record was written.
  Status Finish() const { return error_; }

 private:
  Status Write(const std::string& bytes, uint64_t at);

  const std::string path_;
  int fd_ = -1;
  uint64_t end_ = 0;  // the file's size: the array's closing "]\n" is its last two bytes
  bool empty_ = true;
  Status error_;
};

}  // namespace raystack::master
