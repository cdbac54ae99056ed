#include "common/store/store_writer.h"

#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

#include "common/base/file_lock.h"
#include "common/base/log.h"
#include "common/store/block_codec.h"

namespace raystack::store {
namespace {

std::string Tmp(const std::string& path) { return path + ".tmp"; }

// A store's data files (beside them: the lock file), in the order Finish renames them into
// place: the index last, since a store is whole once it is there.
constexpr const char* kDataFiles[] = {kBlocksFile, kOctreeFile, kLightsFile, kIndexFile};

// Writes the file's .tmp beside it (renamed into place by Finish, once every file is written).
Status WriteTmp(const std::string& path, const char (&magic)[8], const std::vector<uint8_t>& body) {
  FileHeader h{};
  std::memcpy(h.magic, magic, 8);
  h.version = kFormatVersion;
  h.header_bytes = sizeof h;
  h.body_bytes = body.size();
  h.body_checksum = Checksum(body);
  std::FILE* f = std::fopen(Tmp(path).c_str(), "wb");
  if (!f) return Status::Error(path + ": cannot create: " + std::strerror(errno));
  bool ok = std::fwrite(&h, sizeof h, 1, f) == 1 &&
            (body.empty() || std::fwrite(body.data(), body.size(), 1, f) == 1);
  ok = (std::fclose(f) == 0) && ok;
  if (!ok) return Status::Error(Tmp(path) + ": write failed (disk full?)");
  return OkStatus();
}

// Takes the store's lock (the file kLockFile in it, created if missing) without waiting;
// *fd holds it. A filesystem without locks is warned about, and the store written unlocked.
Status LockStore(const std::string& dir, int* fd) {
  std::string error;
  switch (TryLockFile(dir + "/" + kLockFile, /*create=*/true, fd, &error)) {
    case LockResult::kLocked:
      return OkStatus();
    case LockResult::kHeldElsewhere:
      return Status::Error(dir + ": another raystack-prep is writing this store now; wait for it "
                           "or give another -o");
    case LockResult::kNoLocks:
      LOG_WARNING("prep", "%s: its filesystem takes no file locks: nothing keeps two raystack-prep "
                  "from writing this store at once", dir.c_str());
      return OkStatus();
    case LockResult::kNoFile:
    case LockResult::kError:
      break;
  }
  std::error_code ec;
  if (!std::filesystem::exists(dir, ec))  // between its creation and the lock's
    return Status::Error(dir + ": the folder was removed as this raystack-prep opened it (one "
                         "that failed removes the store it created); run it again");
  return Status::Error(error);
}

template <typename T>
void Append(std::vector<uint8_t>* out, const T* data, size_t count) {
  const auto* p = reinterpret_cast<const uint8_t*>(data);
  out->insert(out->end(), p, p + sizeof(T) * count);
}

}  // namespace

Expected<std::unique_ptr<StoreWriter>> StoreWriter::Create(const std::string& dir) {
  std::error_code ec;
  std::unique_ptr<StoreWriter> w(new StoreWriter());
  w->dir_ = dir;
  // Whether the folder the path names existed, not whether creating made some folder: for
  // "old/x/.." create_directories makes old/x, yet the store is old, a user's (review, 2026-11-26).
  const std::filesystem::path target = std::filesystem::weakly_canonical(dir, ec);
  if (ec) return Status::Error(dir + ": cannot resolve the path: " + ec.message());
  w->created_dir_ = !std::filesystem::exists(target, ec);
  std::filesystem::create_directories(dir, ec);
  if (ec) return Status::Error(dir + ": cannot create directory: " + ec.message());
  const bool had_lock = std::filesystem::exists(dir + "/" + kLockFile, ec);
  RAYSTACK_RETURN_IF_ERROR(LockStore(dir, &w->lock_fd_));
  w->created_lock_ = !had_lock;
  // A store being replaced stays whole until Finish: the new files are written beside it as
  // .tmp, and a conversion that fails or is interrupted leaves the old store as it was.
  const std::string path = Tmp(dir + "/" + kBlocksFile);
  w->blocks_ = std::fopen(path.c_str(), "wb");
  if (!w->blocks_) return Status::Error(path + ": cannot create: " + std::strerror(errno));
  std::setvbuf(w->blocks_, nullptr, _IOFBF, 1 << 20);
  FileHeader placeholder{};
  if (std::fwrite(&placeholder, sizeof placeholder, 1, w->blocks_) != 1)
    return Status::Error(path + ": write failed");
  w->offset_ = sizeof placeholder;
  return w;
}

Status StoreWriter::CheckFolderIsForAStore(const std::string& dir) {
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) return OkStatus();  // made by Create
  for (const std::filesystem::directory_entry& e : std::filesystem::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    bool ours = false;
    for (const char* file : kDataFiles) ours |= name == file || name == Tmp(file);
    ours |= name == kLockFile;
    if (!ours)
      return Status::Error(dir + ": holds other files ('" + name + "'): a store needs a folder of "
                           "its own; give a new or empty folder, or a store to replace");
  }
  return OkStatus();
}

uint64_t StoreWriter::LeftoverBytes(const std::string& dir) {
  uint64_t bytes = 0;
  std::error_code ec;
  for (const char* file : kDataFiles) {
    const uint64_t size = std::filesystem::file_size(Tmp(dir + "/" + file), ec);
    if (!ec) bytes += size;
  }
  return bytes;
}

Status StoreWriter::CheckCanWrite(const std::string& dir) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::path at = fs::absolute(dir, ec);
  if (ec) return Status::Error(dir + ": cannot resolve the path: " + ec.message());
  while (!fs::exists(at, ec) && at.has_parent_path() && at != at.parent_path()) at = at.parent_path();
  if (!fs::is_directory(at, ec))
    return Status::Error(dir + ": cannot create directory: " + at.string() + " is not a folder");
  if (::access(at.c_str(), W_OK | X_OK) != 0)
    return Status::Error(dir + ": cannot write in " + at.string() + ": " + std::strerror(errno));
  return OkStatus();
}

Status StoreWriter::CheckNotBeingWritten(const std::string& dir) {
  int fd = -1;
  std::string error;  // (a lock that cannot be tried here is Create's to report)
  const LockResult r = TryLockFile(dir + "/" + kLockFile, /*create=*/false, &fd, &error);
  if (fd >= 0) ::close(fd);  // free again: Create takes it for the writing
  if (r == LockResult::kHeldElsewhere)
    return Status::Error(dir + ": another raystack-prep is writing this store now; wait for it "
                         "or give another -o");
  return OkStatus();
}

StoreWriter::~StoreWriter() {
  if (blocks_) std::fclose(blocks_);
  if (!finished_) RemovePartialStore();
  if (lock_fd_ >= 0) ::close(lock_fd_);
}

void StoreWriter::Abandon() {
  const std::lock_guard lock(mu_);
  abandoned_ = true;
  if (!finished_) RemovePartialStore();
}

// A failed write on a full disk left blocks.bin.tmp holding all the free space. The lock file
// is removed while still held (TryLockFile checks that the file it locked is still there), and
// only when this writer created it: a lock file that was there before may be opened by another
// prep right now. The folder goes only when this writer made it and nothing else is in it.
void StoreWriter::RemovePartialStore() {
  if (lock_fd_ < 0) return;  // not locked: the files may be another writer's
  std::error_code ec;
  for (const char* file : kDataFiles) {
    std::filesystem::remove(Tmp(dir_ + "/" + file), ec);
    if (created_dir_) std::filesystem::remove(dir_ + "/" + file, ec);
  }
  if (created_lock_ || created_dir_)
    std::filesystem::remove(dir_ + "/" + kLockFile, ec);
  if (created_dir_) std::filesystem::remove(dir_, ec);  // fails, as wanted, unless empty
}

Status StoreWriter::Add(const EncodedBlock& b) {
  if (b.id != entries_.size())
    return Status::Error(StrFormat("internal: block %u written out of order", b.id));
  if (std::fwrite(b.stored.data(), 1, b.stored.size(), blocks_) != b.stored.size())
    return Status::Error(dir_ + "/" + kBlocksFile + ": write failed (disk full?): " +
                         std::strerror(errno));
  BlockEntry e{};
  e.offset = offset_;
  e.stored_bytes = static_cast<uint32_t>(b.stored.size());
  e.raw_bytes = b.raw_bytes;
  for (int a = 0; a < 3; ++a) {
    e.cell_lower[a] = b.cell.lower[a];
    e.cell_upper[a] = b.cell.upper[a];
    e.bounds_lower[a] = b.bounds.lower[a];
    e.bounds_upper[a] = b.bounds.upper[a];
  }
  e.triangle_count = b.triangles;
  e.octree_leaf = b.octree_leaf;
  e.checksum = Checksum(b.stored);
  entries_.push_back(e);
  offset_ += b.stored.size();
  return OkStatus();
}

Status StoreWriter::Finish(StoreSummary s, std::span<const OctreeNode> octree,
                           std::span<const MaterialRecord> materials,
                           std::span<const EmitterRecord> emitters) {
  const std::string blocks_path = dir_ + "/" + kBlocksFile;
  FileHeader h{};
  std::memcpy(h.magic, kBlocksMagic, 8);
  h.version = kFormatVersion;
  h.header_bytes = sizeof h;
  h.body_bytes = offset_ - sizeof h;
  bool ok = std::fflush(blocks_) == 0 && std::fseek(blocks_, 0, SEEK_SET) == 0 &&
            std::fwrite(&h, sizeof h, 1, blocks_) == 1;
  ok = (std::fclose(blocks_) == 0) && ok;
  blocks_ = nullptr;
  if (!ok) return Status::Error(Tmp(blocks_path) + ": write failed (disk full?)");

  std::vector<uint8_t> body;
  Append(&body, octree.data(), octree.size());
  RAYSTACK_RETURN_IF_ERROR(WriteTmp(dir_ + "/" + kOctreeFile, kOctreeMagic, body));
  // Always written, empty too, so that an older store's lights.bin never outlives it; index.bin
  // names it by checksum, so a lights.bin of another conversion is never taken for this one's.
  body.clear();
  Append(&body, emitters.data(), emitters.size());
  RAYSTACK_RETURN_IF_ERROR(WriteTmp(dir_ + "/" + kLightsFile, kLightsMagic, body));
  s.lights_checksum = static_cast<uint32_t>(Checksum(body)) | 1u;

  s.block_count = static_cast<uint32_t>(entries_.size());
  s.octree_node_count = static_cast<uint32_t>(octree.size());
  s.material_count = static_cast<uint32_t>(materials.size());
  s.references = s.raw_bytes = s.stored_bytes = 0;
  for (const BlockEntry& e : entries_) {
    s.references += e.triangle_count;
    s.raw_bytes += e.raw_bytes;
    s.stored_bytes += e.stored_bytes;
  }
  body.clear();
  Append(&body, &s, 1);
  Append(&body, materials.data(), materials.size());
  Append(&body, entries_.data(), entries_.size());
  RAYSTACK_RETURN_IF_ERROR(WriteTmp(dir_ + "/" + kIndexFile, kIndexMagic, body));

  const std::lock_guard lock(mu_);  // an interrupt's Abandon waits for the renames
  // Abandoned while the last files were written (an interrupt's clean-up removed them): the
  // old store must not lose its index for a swap that cannot happen.
  if (abandoned_) return Status::Error(dir_ + ": the conversion was interrupted");
  // Every file is written: now the swap. A folder with an index.bin holds a complete store, so
  // the old index goes first and the new one comes last; between the two (a few renames) the
  // folder holds no store, never a mix of two.
  std::error_code ec;
  std::filesystem::remove(dir_ + "/" + kIndexFile, ec);
  if (ec) return Status::Error(dir_ + "/" + kIndexFile + ": cannot remove the old one: " + ec.message());
  for (const char* file : kDataFiles) {
    const std::string to = dir_ + "/" + file;
    if (std::rename(Tmp(to).c_str(), to.c_str()) != 0)
      return Status::Error(to + ": cannot rename into place: " + std::strerror(errno));
  }
  finished_ = true;
  return OkStatus();
}

}  // namespace raystack::store
