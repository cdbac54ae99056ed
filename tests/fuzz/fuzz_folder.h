#pragma once
// A private temporary folder for fuzz targets whose code under test reads files: created on
// first use, removed with its content when the process exits (libFuzzer ends with exit()).

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <span>
#include <string>

#include "common/base/check.h"

namespace raystack::fuzz {

inline std::string& FolderName() {
  static std::string folder;
  return folder;
}

inline void RemoveFolder() {
  std::error_code ignored;
  std::filesystem::remove_all(FolderName(), ignored);
}

inline const std::string& Folder() {
  static const std::string& folder = []() -> const std::string& {
    std::string& name = FolderName();  // constructed before the atexit call: outlives the handler
    char pattern[] = "/tmp/raystack-fuzz-XXXXXX";
    const char* made = mkdtemp(pattern);
    CHECK(made != nullptr);
    name = made;
    std::atexit(RemoveFolder);
    return name;
  }();
  return folder;
}

// Writes `head` then `body` to `path` (replacing it).
inline void WriteFile(const std::string& path, std::span<const uint8_t> head,
                      std::span<const uint8_t> body) {
  FILE* file = std::fopen(path.c_str(), "wb");
  CHECK(file != nullptr);
  // (An empty span's data() may be null, which fwrite must not be given even for 0 bytes:
  // UBSan stopped the corpus replay at its first input.)
  for (const std::span<const uint8_t> part : {head, body})
    if (!part.empty()) CHECK(std::fwrite(part.data(), 1, part.size(), file) == part.size());
  CHECK(std::fclose(file) == 0);
}

}  // namespace raystack::fuzz
