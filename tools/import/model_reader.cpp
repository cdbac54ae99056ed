#include "tools/import/model_reader.h"

#include <algorithm>
#include <cctype>
#include <filesystem>

#include "tools/import/buffered_input.h"
#include "tools/import/obj_reader.h"
#include "tools/import/ply_reader.h"

namespace raystack::import {
namespace {

std::string LowerExtension(const std::string& path) {
  std::string extension = std::filesystem::path(path).extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return extension;
}

}  // namespace

Status ReadModel(const std::string& path, const ReadOptions& options, TriangleSink& sink,
                 ModelInfo* info) {
  *info = ModelInfo{};
  Expected<BufferedInput> input = BufferedInput::Open(path, options.progress);
  if (!input.ok()) return input.status();
  if (input->file_size() == 0) return Status::Error(path + ": file is empty");
  // Content first: PLY has a magic word, whatever the file is called.
  if (input->Peek(3) == "ply") return ReadPly(*input, options, sink, info);
  if (input->Peek(2) == "\x1f\x8b")  // (scans are often shared gzipped, whatever they are called)
    return Status::Error(path + ": compressed with gzip: decompress it first (gunzip -k " + path + ")");
  if (LowerExtension(path) == ".obj") return ReadObj(*input, options, sink, info);
  return Status::Error(path + ": unknown model format (expected a .obj file or a PLY file)");
}

}  // namespace raystack::import
