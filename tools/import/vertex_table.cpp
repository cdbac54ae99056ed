#include "tools/import/vertex_table.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <limits>

#include "common/base/check.h"
#include "common/base/log.h"

namespace raystack::import {
namespace {

constexpr uint64_t kNoLine = std::numeric_limits<uint64_t>::max();

// pwrite/pread loop until the whole page moved (they may transfer less than asked).
Status WriteAll(int fd, const void* data, size_t bytes, uint64_t offset, const std::string& path) {
  const char* p = static_cast<const char*>(data);
  while (bytes > 0) {
    ssize_t n = ::pwrite(fd, p, bytes, static_cast<off_t>(offset));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return Status::Error("cannot write vertex spill file " + path + ": " +
                                     std::strerror(errno));
    p += n;
    bytes -= static_cast<size_t>(n);
    offset += static_cast<uint64_t>(n);
  }
  return OkStatus();
}

Status ReadAll(int fd, void* data, size_t bytes, uint64_t offset, const std::string& path) {
  char* p = static_cast<char*>(data);
  while (bytes > 0) {
    ssize_t n = ::pread(fd, p, bytes, static_cast<off_t>(offset));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return Status::Error("cannot read vertex spill file " + path + ": " +
                                     (n == 0 ? std::string("short file") : std::strerror(errno)));
    p += n;
    bytes -= static_cast<size_t>(n);
    offset += static_cast<uint64_t>(n);
  }
  return OkStatus();
}

}  // namespace

VertexTable::VertexTable(int floats_per_vertex, MemoryBudget* budget, std::string temp_parent)
    : floats_(floats_per_vertex),
      records_per_page_(kPageBytes / (sizeof(float) * static_cast<size_t>(floats_per_vertex))),
      budget_(budget), temp_parent_(std::move(temp_parent)) {
  CHECK(floats_per_vertex > 0 && floats_per_vertex <= kMaxFloatsPerVertex);
}

VertexTable::~VertexTable() {
  budget_->Release(ram_pages_.size() * kPageBytes + cache_reserved_);
  if (fd_ >= 0) ::close(fd_);
}

Status VertexTable::Append(const float* values) {
  size_t slot = static_cast<size_t>(size_ % records_per_page_);
  if (slot == 0) RAYSTACK_RETURN_IF_ERROR(StartNewPage());
  float* page = spilled() ? tail_.get() : ram_pages_.back().get();
  std::memcpy(page + slot * static_cast<size_t>(floats_), values,
              sizeof(float) * static_cast<size_t>(floats_));
  ++size_;
  return OkStatus();
}

Status VertexTable::StartNewPage() {
  if (spilled()) {
    if (size_ > 0) RAYSTACK_RETURN_IF_ERROR(FlushTailPage());
    return OkStatus();
  }
  if (budget_->TryReserve(kPageBytes)) {
    ram_pages_.emplace_back(new float[kPageBytes / sizeof(float)]());  // zeroed: whole pages may be written
    return OkStatus();
  }
  return Spill();
}

// Moves every RAM page to the file (they are all full: a new page was just refused) and
// switches to the tail buffer plus page cache.
Status VertexTable::Spill() {
  Expected<TempDir> dir = TempDir::Create(temp_parent_);
  if (!dir.ok()) return dir.status();
  temp_dir_.emplace(std::move(dir).value());
  std::string path = temp_dir_->File("vertices.bin");
  fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
  if (fd_ < 0) return Status::Error("cannot create vertex spill file " + path + ": " +
                                    std::strerror(errno));
  for (const auto& page : ram_pages_) {
    RAYSTACK_RETURN_IF_ERROR(WriteAll(fd_, page.get(), kPageBytes,
                                      flushed_pages_ * kPageBytes, path));
    ++flushed_pages_;
  }
  budget_->Release(ram_pages_.size() * kPageBytes);
  ram_pages_.clear();
  ram_pages_.shrink_to_fit();
  tail_.reset(new float[kPageBytes / sizeof(float)]());
  // Half of what the budget has left (the other tables of the read may spill too), no more
  // than the file will hold.
  const uint64_t wanted = std::min<uint64_t>((budget_->limit() - budget_->used()) / 2,
                                             (flushed_pages_ + 16) * kPageBytes);
  cache_reserved_ = wanted > kMinCacheLines * kLineBytes && budget_->TryReserve(wanted - kMinCacheLines * kLineBytes)
                        ? wanted - kMinCacheLines * kLineBytes
                        : 0;
  cache_lines_ = kMinCacheLines + static_cast<size_t>(cache_reserved_ / kLineBytes);
  cache_.reset(new char[cache_lines_ * kLineBytes]);
  cache_tags_.assign(cache_lines_, kNoLine);
  LOG_DEBUG("import", "vertex table spilled %llu vertices to %s",
            static_cast<unsigned long long>(size_), path.c_str());
  return OkStatus();
}

Status VertexTable::FlushTailPage() {
  RAYSTACK_RETURN_IF_ERROR(WriteAll(fd_, tail_.get(), kPageBytes, flushed_pages_ * kPageBytes,
                                    temp_dir_->File("vertices.bin")));
  ++flushed_pages_;
  return OkStatus();
}

Expected<const char*> VertexTable::Line(uint64_t line) {
  const size_t slot = static_cast<size_t>(line % cache_lines_);
  char* cached = cache_.get() + slot * kLineBytes;
  if (cache_tags_[slot] != line) {
    cache_tags_[slot] = kNoLine;  // stays invalid if the read fails
    RAYSTACK_RETURN_IF_ERROR(ReadAll(fd_, cached, kLineBytes, line * kLineBytes,
                                     temp_dir_->File("vertices.bin")));
    cache_tags_[slot] = line;
  }
  return static_cast<const char*>(cached);
}

Status VertexTable::GetSpilled(uint64_t page, size_t slot, float* out) {
  const size_t record_bytes = sizeof(float) * static_cast<size_t>(floats_);
  if (page == flushed_pages_) {  // not written yet
    std::memcpy(out, tail_.get() + slot * static_cast<size_t>(floats_), record_bytes);
    return OkStatus();
  }
  // The record's bytes in the file, from one line or two (pages are whole lines).
  const uint64_t begin = page * kPageBytes + slot * record_bytes;
  char* to = reinterpret_cast<char*>(out);
  for (uint64_t at = begin; at < begin + record_bytes;) {
    Expected<const char*> line = Line(at / kLineBytes);
    if (!line.ok()) return line.status();
    const size_t in_line = static_cast<size_t>(at % kLineBytes);
    const size_t n = std::min<size_t>(kLineBytes - in_line, static_cast<size_t>(begin + record_bytes - at));
    std::memcpy(to, *line + in_line, n);
    to += n;
    at += n;
  }
  return OkStatus();
}

}  // namespace raystack::import
