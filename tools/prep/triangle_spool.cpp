#include "tools/prep/triangle_spool.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "tools/prep/write_behind.h"

namespace raystack::prep {
namespace {
constexpr size_t kFileBuffer = 1 << 20;
constexpr size_t kBatch = 8192;
}  // namespace

TriangleSpool::TriangleSpool(std::string path, uint64_t memory_budget, size_t file_buffer)
    : path_(std::move(path)), memory_budget_(memory_budget), file_buffer_(file_buffer) {}

TriangleSpool::TriangleSpool(std::string path, WriteBehind& writer)
    : path_(std::move(path)), memory_budget_(0), file_buffer_(0), writer_(&writer) {}

TriangleSpool::TriangleSpool(TriangleSpool&& o) noexcept
    : path_(std::move(o.path_)), memory_budget_(o.memory_budget_), file_buffer_(o.file_buffer_),
      memory_(std::move(o.memory_)),
      file_(o.file_), writer_(o.writer_), fd_(o.fd_), pending_(std::move(o.pending_)),
      spilled_(o.spilled_), triangles_(o.triangles_), bytes_(o.bytes_),
      has_attributes_(o.has_attributes_) {
  o.file_ = nullptr;
  o.fd_ = -1;
  o.spilled_ = false;
  o.path_.clear();
}

TriangleSpool::~TriangleSpool() { Clear(); }

void TriangleSpool::Clear() {
  if (file_) std::fclose(file_);
  file_ = nullptr;
  if (fd_ >= 0) {
    // Writes still queued for this file must not land in a recycled descriptor.
    (void)writer_->Flush();
    ::close(fd_);
  }
  fd_ = -1;
  std::vector<uint8_t>().swap(pending_);
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

Status TriangleSpool::AppendBehind(const PackedTriangle& t, const TriangleAttributes* attributes,
                                   bool with_attributes) {
  if (fd_ < 0) {
    if (spilled_) return Status::Error(path_ + ": appending to a closed spool");
    fd_ = ::open(path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    if (fd_ < 0) return Status::Error(path_ + ": cannot create temporary file: " + std::strerror(errno));
    spilled_ = true;
    pending_ = writer_->Take();
  }
  const size_t n = sizeof t + (with_attributes ? sizeof *attributes : 0);
  if (pending_.size() + n > writer_->buffer_bytes()) {
    RAYSTACK_RETURN_IF_ERROR(writer_->Write(fd_, path_, std::move(pending_)));
    pending_ = writer_->Take();
  }
  const auto* bytes = reinterpret_cast<const uint8_t*>(&t);
  pending_.insert(pending_.end(), bytes, bytes + sizeof t);
  if (with_attributes) {
    const auto* extra = reinterpret_cast<const uint8_t*>(attributes);
    pending_.insert(pending_.end(), extra, extra + sizeof *attributes);
  }
  return OkStatus();
}

Status TriangleSpool::Append(const PackedTriangle& t, const TriangleAttributes* attributes) {
  const bool with_attributes = t.has_normals() || t.has_uvs();
  has_attributes_ |= with_attributes;
  const size_t n = sizeof t + (with_attributes ? sizeof *attributes : 0);
  ++triangles_;
  bytes_ += n;
  if (writer_) return AppendBehind(t, attributes, with_attributes);
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
  if (fd_ >= 0) {
    if (!pending_.empty()) (void)writer_->Write(fd_, path_, std::move(pending_));  // Flush says
    std::vector<uint8_t>().swap(pending_);
    const Status written = writer_->Flush();
    const bool closed = ::close(fd_) == 0;
    fd_ = -1;
    if (!written.ok()) return written;
    if (!closed) return Status::Error(path_ + ": write failed (disk full?)");
    return OkStatus();
  }
  if (!file_) return OkStatus();
  const bool failed = std::fflush(file_) != 0 || std::ferror(file_);
  std::fclose(file_);
  file_ = nullptr;
  if (failed) return Status::Error(path_ + ": write failed (disk full?)");
  return OkStatus();
}

Status TriangleSpool::ForEachPlain(uint64_t first, uint64_t count, const Visitor& visit) const {
  std::vector<PackedTriangle> tris(kBatch);
  if (!spilled_) {
    const uint64_t end = first + count;
    for (uint64_t at = first; at < end; at += kBatch) {
      const size_t n = static_cast<size_t>(std::min<uint64_t>(kBatch, end - at));
      std::memcpy(tris.data(), memory_.data() + at * sizeof(PackedTriangle), n * sizeof(PackedTriangle));
      RAYSTACK_RETURN_IF_ERROR(visit(std::span<const PackedTriangle>(tris.data(), n), {}));
    }
    return OkStatus();
  }
  std::FILE* f = std::fopen(path_.c_str(), "rb");
  if (!f) return Status::Error(path_ + ": cannot reopen temporary file: " + std::strerror(errno));
  if (first > 0 && fseeko(f, static_cast<off_t>(first * sizeof(PackedTriangle)), SEEK_SET) != 0) {
    std::fclose(f);
    return Status::Error(path_ + ": temporary file is damaged (cannot seek)");
  }
  uint64_t seen = 0;
  Status status;
  while (seen < count) {
    const size_t n = std::fread(tris.data(), sizeof(PackedTriangle),
                                static_cast<size_t>(std::min<uint64_t>(kBatch, count - seen)), f);
    if (n == 0) break;
    seen += n;
    status = visit(std::span<const PackedTriangle>(tris.data(), n), {});
    if (!status.ok()) break;
  }
  // A range that ends where the spool does must end where the file does.
  const bool whole = first + count == triangles_;
  const bool damaged = std::ferror(f) || (whole && std::fgetc(f) != EOF);
  std::fclose(f);
  if (!status.ok()) return status;
  if (damaged || seen != count) return Status::Error(path_ + ": temporary file is damaged");
  return OkStatus();
}

Status TriangleSpool::ForEachRange(uint64_t first, uint64_t count, const Visitor& visit) const {
  if (has_attributes_)
    return Status::Error(path_ + ": records of different sizes cannot be read by range");
  if (first > triangles_ || count > triangles_ - first)
    return Status::Error(path_ + ": range beyond the spool's end");
  return ForEachPlain(first, count, visit);
}

Status TriangleSpool::ForEach(const Visitor& visit) const {
  // Without attributes every record is one PackedTriangle: batches are read in one piece.
  if (!has_attributes_) return ForEachPlain(0, triangles_, visit);
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
