#pragma once
// --stats: a JSON array of one record per frame, each written once its frame's image is. After
// every record the file is a whole JSON array, so a run that fails, is interrupted or is killed
// keeps the figures of the frames it finished, and no frame's record is held in memory (the
// file was written once, at the end: a run of 10,000 frames kept them all, and a crash lost
// them all). A pipe or a terminal (`--stats /dev/stdout`) gets the records as they come and the
// closing bracket at the end.

#include <cstdint>
#include <mutex>
#include <string>

#include "common/base/output_target.h"
#include "common/base/status.h"

namespace raystack::master {


class StatsFile {
 public:
  // Nothing is written with an empty `path`. A file is replaced at the first record (written
  // aside, then renamed over it), so a run that fails before any frame ends, or whose first
  // write fails, leaves an earlier file as it was.
  explicit StatsFile(std::string path) : path_(std::move(path)) {}
  ~StatsFile();  // closes a stream's array
  StatsFile(const StatsFile&) = delete;
  StatsFile& operator=(const StatsFile&) = delete;

  // Adds `record` (a JSON object) at the end of the array; from any thread. A failed write is
  // said once, as a warning; the run goes on (its images matter more) and Finish returns the
  // error.
  void Append(const std::string& record);
  // Closes a stream's array; the first write error, naming the file, or OK.
  Status Finish();

 private:
  Status Open();
  Status Write(const std::string& bytes, uint64_t at);
  void Fail(Status why);

  const std::string path_;
  OutputTarget target_;
  std::mutex mu_;
  int fd_ = -1;
  bool closed_ = false;  // a stream's closing bracket is out
  uint64_t end_ = 0;     // a regular file's size: its closing "]\n" is its last two bytes
  bool empty_ = true;
  Status error_;
};

}  // namespace raystack::master
