#include "tools/prep/triangle_spool.h"

#include <cerrno>
#include <cstring>

namespace raystack::prep {
namespace {
constexpr size_t kFileBuffer = 1 << 20;
constexpr size_t kBatch = 8192;
}  // namespace

TriangleSpool::TriangleSpool(std::string path, uint64_t memory_budget, size_t file_buffer)
    : path_(std::move(path)), memory_budget_(memory_budget), file_buffer_(file_buffer) {}

TriangleSpool::TriangleSpool(TriangleSpool&& o) noexcept
    : path_(std::move(o.path_)), memory_budget_(o.memory_budget_), file_buffer_(o.file_buffer_),
      memory_(std::move(o.memory_)),
      file_(o.file_), spilled_(o.spilled_), triangles_(o.triangles_), bytes_(o.bytes_),
      has_attributes_(o.has_attributes_) {
  o.file_ = nullptr;
  o.spilled_ = false;
  o.path_.clear();
}

TriangleSpool::~TriangleSpool() { Clear(); }

void TriangleSpool::Clear() {
  if (file_) std::fclose(file_);
  file_ = nullptr;
  if (spilled_ && !path_.empty()) std::remove(path_.c_str());
  spilled_ = false;
  std::vector<uint8_t>().swap(memory_);
  triangles_ = bytes_ = 0;
  has_attributes_ = false;
}

Status TriangleSpool::Spill() {
  file_ = std::fopen(path_.c_str(), "wb");
  if (!file_) return Status::Error(path_ + ": cannot create temporary file: " + std::strerror(errno));
  spilled_ = true;
  std::setvbuf(file_, nullptr, _IOFBF, file_buffer_);
  if (!memory_.empty() && std::fwrite(memory_.data(), 1, memory_.size(), file_) != memory_.size())
    return Status::Error(path_ + ": write failed (disk full?): " + std::strerror(errno));
  std::vector<uint8_t>().swap(memory_);
  return OkStatus();
}

Status TriangleSpool::Append(const PackedTriangle& t, const TriangleAttributes* attributes) {
  const bool with_attributes = t.has_normals() || t.has_uvs();
  has_attributes_ |= with_attributes;
  const size_t n = sizeof t + (with_attributes ? sizeof *attributes : 0);
  ++triangles_;
  bytes_ += n;
  if (!file_) {
    if (memory_.size() + n <= memory_budget_) {
      const size_t at = memory_.size();
      memory_.resize(at + n);
      std::memcpy(memory_.data() + at, &t, sizeof t);
      if (with_attributes) std::memcpy(memory_.data() + at + sizeof t, attributes, sizeof *attributes);
      return OkStatus();
    }
    RAYSTACK_RETURN_IF_ERROR(Spill());
  }
  if (std::fwrite(&t, sizeof t, 1, file_) != 1 ||
      (with_attributes && std::fwrite(attributes, sizeof *attributes, 1, file_) != 1))
    return Status::Error(path_ + ": write failed (disk full?): " + std::strerror(errno));
  return OkStatus();
}

Status TriangleSpool::Close() {
  if (!file_) return OkStatus();
  const bool failed = std::fflush(file_) != 0 || std::ferror(file_);
  std::fclose(file_);
  file_ = nullptr;
  if (failed) return Status::Error(path_ + ": write failed (disk full?)");
  return OkStatus();
}

Status TriangleSpool::ForEach(const Visitor& visit) const {
  std::vector<PackedTriangle> tris;
  std::vector<TriangleAttributes> attrs;
  tris.reserve(kBatch);
  attrs.reserve(kBatch);
  auto flush = [&]() -> Status {
    if (tris.empty()) return OkStatus();
    Status s = visit(tris, attrs);
    tris.clear();
    attrs.clear();
    return s;
  };
  auto take = [&](const uint8_t* p, size_t left, size_t* used) -> bool {
    PackedTriangle t;
    if (left < sizeof t) return false;
    std::memcpy(&t, p, sizeof t);
    size_t n = sizeof t;
    TriangleAttributes a{};
    if (t.has_normals() || t.has_uvs()) {
      if (left < n + sizeof a) return false;
      std::memcpy(&a, p + n, sizeof a);
      n += sizeof a;
    }
    tris.push_back(t);
    if (has_attributes_) attrs.push_back(a);
    *used = n;
    return true;
  };

  if (!spilled_) {
    size_t at = 0, used = 0;
    while (at < memory_.size() && take(memory_.data() + at, memory_.size() - at, &used)) {
      at += used;
      if (tris.size() == kBatch) RAYSTACK_RETURN_IF_ERROR(flush());
    }
    return flush();
  }
  std::FILE* f = std::fopen(path_.c_str(), "rb");
  if (!f) return Status::Error(path_ + ": cannot reopen temporary file: " + std::strerror(errno));
  std::vector<uint8_t> buffer(kFileBuffer);
  size_t have = 0;
  Status status;
  for (;;) {
    const size_t got = std::fread(buffer.data() + have, 1, buffer.size() - have, f);
    have += got;
    size_t at = 0, used = 0;
    while (take(buffer.data() + at, have - at, &used)) {
      at += used;
      if (tris.size() == kBatch) {
        status = flush();
        if (!status.ok()) break;
      }
    }
    if (!status.ok()) break;
    std::memmove(buffer.data(), buffer.data() + at, have - at);
    have -= at;
    if (got == 0) break;
  }
  const bool read_error = std::ferror(f);
  std::fclose(f);
  if (!status.ok()) return status;
  if (read_error || have != 0) return Status::Error(path_ + ": temporary file is damaged");
  return flush();
}

}  // namespace raystack::prep
