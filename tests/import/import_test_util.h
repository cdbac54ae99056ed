#pragma once
// Helpers shared by the import tests: a sink that keeps everything, and files written into a
// private temporary folder.

#include <gtest/gtest.h>

#include <fstream>
#include <string>
#include <vector>

#include "common/base/temp_dir.h"
#include "tools/import/model_reader.h"

namespace raystack::import {

class CollectingSink : public TriangleSink {
 public:
  Status Consume(std::span<const SourceTriangle> batch) override {
    ++batches;
    triangles.insert(triangles.end(), batch.begin(), batch.end());
    return OkStatus();
  }
  std::vector<SourceTriangle> triangles;
  int batches = 0;
};

class ScratchFiles {
 public:
  ScratchFiles() : dir_(TempDir::Create().value()) {}
  // Writes `bytes` to a file called `name` in the folder and returns its path.
  std::string Write(const std::string& name, const std::string& bytes) const {
    std::string path = dir_.File(name);
    std::ofstream(path, std::ios::binary) << bytes;
    return path;
  }
  const std::string& path() const { return dir_.path(); }

 private:
  TempDir dir_;
};

// Reads `path` into `sink` and `info` with the given options.
inline Status ReadFile(const std::string& path, CollectingSink* sink, ModelInfo* info,
                       const ReadOptions& options = {}) {
  return ReadModel(path, options, *sink, info);
}

// Every field equal (padding aside), attributes only where present.
inline bool SameTriangle(const SourceTriangle& a, const SourceTriangle& b) {
  if (a.material != b.material || a.has_normals != b.has_normals || a.has_uvs != b.has_uvs)
    return false;
  for (int k = 0; k < 3; ++k) {
    if (!(a.p[k] == b.p[k])) return false;
    if (a.has_normals && !(a.n[k] == b.n[k])) return false;
    if (a.has_uvs && (a.uv[k][0] != b.uv[k][0] || a.uv[k][1] != b.uv[k][1])) return false;
  }
  return true;
}

// Expects a failed status whose message contains every one of `parts`.
inline void ExpectErrorMentions(const Status& status, const std::vector<std::string>& parts) {
  ASSERT_FALSE(status.ok()) << "expected an error";
  for (const std::string& part : parts)
    EXPECT_NE(status.message().find(part), std::string::npos)
        << "message '" << status.message() << "' lacks '" << part << "'";
}

}  // namespace raystack::import
