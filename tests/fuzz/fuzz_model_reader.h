#pragma once
// Shared body of the OBJ and PLY fuzz targets: the readers stream from a file, so each input
// is written to a file in a private temporary folder and read back through a 4 KB buffer
// (lines and binary records then cross buffer refills all the time; the default 4 MB buffer
// would also cost more per run than the parse) with a small vertex budget, so the
// spill-to-disk path runs too. A sink checks what arrives.

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <span>
#include <string>

#include "common/base/check.h"
#include "tests/fuzz/fuzz_folder.h"
#include "tools/import/buffered_input.h"
#include "tools/import/model_reader.h"
#include "tools/import/obj_reader.h"
#include "tools/import/ply_reader.h"

namespace raystack::fuzz {

// Every triangle a reader accepts has finite vertices (the readers promise to reject NaN and
// Inf): checking it here turns a broken promise into a crash the fuzzer reports.
class CheckingSink : public import::TriangleSink {
 public:
  Status Consume(std::span<const import::SourceTriangle> batch) override {
    for (const import::SourceTriangle& t : batch) {
      for (const Vec3f& p : t.p) {
        CHECK(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z));
      }
    }
    return OkStatus();
  }
};

// Writes `data` to `<temp folder>/input.obj` (or .ply) and reads it as an OBJ (or a PLY).
inline void ReadModelFromBytes(const uint8_t* data, size_t size, bool ply) {
  const char* extension = ply ? ".ply" : ".obj";
  const std::string& folder = Folder();
  const std::string path = folder + "/input" + extension;
  WriteFile(path, {}, {data, size});

  import::ReadOptions options;
  options.vertex_memory_bytes = 64 << 10;  // spill beyond a few thousand vertices
  options.temp_dir = folder;
  CheckingSink sink;
  import::ModelInfo info;
  Expected<import::BufferedInput> input = import::BufferedInput::Open(path, nullptr, 4096);
  CHECK(input.ok());
  // An error is a fine outcome; it must name the file.
  const Status status = ply ? import::ReadPly(*input, options, sink, &info)
                            : import::ReadObj(*input, options, sink, &info);
  if (!status.ok()) CHECK(status.message().find(path) != std::string::npos);
}

}  // namespace raystack::fuzz
