#pragma once
// A store as a raystack-prep from before lights.bin wrote it: the same blocks, no lights.bin,
// and an index.bin that does not name one (StoreSummary::lights_checksum 0, resealed). For the
// tests of what a renderer does with such a store (path tracing finds its emitters only by
// the rays that meet them). And any other change to a store's summary, resealed.

#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "common/store/block_codec.h"
#include "common/store/format.h"

namespace raystack::testing {

// The bytes of `path` (empty when it cannot be read).
inline std::vector<uint8_t> ReadWholeFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) return {};
  std::vector<uint8_t> bytes(static_cast<size_t>(in.tellg()));
  in.seekg(0);
  in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  return in ? bytes : std::vector<uint8_t>{};
}

// Copies the store `from` to `to` (which must not exist) as an older converter would have
// written it; false when a file could not be read or written.
// Rewrites the StoreSummary in `dir`'s index.bin with `change` applied, checksum and all.
template <typename Change>
bool RewriteSummary(const std::string& dir, Change&& change) {
  const std::string index = dir + "/" + store::kIndexFile;
  std::vector<uint8_t> bytes = ReadWholeFile(index);
  if (bytes.size() < sizeof(store::FileHeader) + sizeof(store::StoreSummary)) return false;
  store::StoreSummary summary;
  uint8_t* body = bytes.data() + sizeof(store::FileHeader);
  std::memcpy(&summary, body, sizeof summary);
  change(&summary);
  std::memcpy(body, &summary, sizeof summary);
  store::FileHeader header;
  std::memcpy(&header, bytes.data(), sizeof header);
  header.body_checksum =
      store::Checksum({body, bytes.size() - sizeof(store::FileHeader)});
  std::memcpy(bytes.data(), &header, sizeof header);
  std::ofstream out(index, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  return static_cast<bool>(out);
}

inline bool CopyAsOlderStore(const std::string& from, const std::string& to) {
  std::error_code ec;
  std::filesystem::copy(from, to, ec);
  if (ec) return false;
  std::filesystem::remove(to + "/" + store::kLightsFile, ec);
  return RewriteSummary(to, [](store::StoreSummary* summary) { summary->lights_checksum = 0; });
}

}  // namespace raystack::testing
