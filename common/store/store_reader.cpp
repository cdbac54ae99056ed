#include "common/store/store_reader.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <new>

#include "common/base/log.h"

namespace raystack::store {

std::string NoStoreThere(const std::string& dir) {
  namespace fs = std::filesystem;
  const std::string convert = "convert a model into it with raystack-prep MODEL -o " + dir;
  std::error_code ec;
  const fs::file_status st = fs::status(dir, ec);
  if (!fs::exists(st)) return "no such folder (" + convert + ")";
  if (!fs::is_directory(st))
    return "is a file, not a block store (a store is the folder raystack-prep writes: "
           "raystack-prep " + dir + " -o STORE)";
  if (!fs::exists(fs::path(dir) / kIndexFile, ec)) {
    // A conversion under way (or one that ended without finishing) writes its files as .tmp.
    for (const char* file : {kBlocksFile, kIndexFile})
      if (fs::exists(fs::path(dir) / (std::string(file) + ".tmp"), ec))
        return "holds no complete block store: raystack-prep is writing one there (or was "
               "interrupted: its " + std::string(file) + ".tmp is there; run it again)";
    return "holds no block store (no " + std::string(kIndexFile) + "; " + convert + ")";
  }
  return "";
}

uint8_t* DirectBuffer::Reserve(uint64_t bytes) {
  if (bytes > capacity_) {
    data_.reset(static_cast<uint8_t*>(std::aligned_alloc(kDirectAlign, bytes)));
    if (data_ == nullptr) throw std::bad_alloc();  // the read's to report, not a crash
    capacity_ = bytes;
  }
  return data_.get();
}

void DirectBuffer::Free::operator()(uint8_t* p) const { std::free(p); }

namespace {

// A file whose body is not the size its header says: cut short, or with bytes after it.
Status SizeMismatch(const std::string& path, uint64_t body, uint64_t said) {
  return Status::Error(body < said
                           ? StrFormat("%s: %llu bytes shorter than its header says (truncated?)",
                                       path.c_str(), static_cast<unsigned long long>(said - body))
                           : StrFormat("%s: %llu bytes longer than its header says (appended to?)",
                                       path.c_str(), static_cast<unsigned long long>(body - said)));
}

// Opens a store file for reading; only a regular file is one. O_NONBLOCK so that a FIFO in a
// store's place does not block the open forever (it has no effect on a regular file's reads).
// A file missing beside a prep's temporary is named as an interrupted prep's leftover.
Status OpenStoreFile(const std::string& path, int flags, int* fd_out, struct stat* st) {
  const int fd = ::open(path.c_str(), flags | O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) {
    const int error = errno;
    const std::string dir = path.substr(0, path.rfind('/') + 1);
    for (const char* file : {kBlocksFile, kIndexFile, kOctreeFile}) {
      struct stat tmp {};
      const std::string leftover = dir + file + ".tmp";
      if (error == ENOENT && ::stat(leftover.c_str(), &tmp) == 0)
        return Status::Error(path + ": missing, and " + leftover + " is there: the store is "
                             "incomplete (a raystack-prep was interrupted?); convert it again");
    }
    return Status::Error(path + ": cannot open: " + std::strerror(error));
  }
  ::fstat(fd, st);
  if (!S_ISREG(st->st_mode)) {
    ::close(fd);
    return Status::Error(path + (S_ISDIR(st->st_mode)
                                     ? ": is a folder, not a store file"
                                     : ": is not a regular file (a FIFO, device or socket)"));
  }
  *fd_out = fd;
  return OkStatus();
}

// Reads a whole small file (index or octree), checks its FileHeader and body checksum.
Status ReadChecked(const std::string& path, const char (&magic)[8], std::vector<uint8_t>* body) {
  int fd = -1;
  struct stat st {};
  RAYSTACK_RETURN_IF_ERROR(OpenStoreFile(path, 0, &fd, &st));
  const uint64_t size = static_cast<uint64_t>(st.st_size);
  FileHeader h{};
  Status status;
  if (size < sizeof h || ::pread(fd, &h, sizeof h, 0) != static_cast<ssize_t>(sizeof h)) {
    status = Status::Error(path + ": truncated header (not a raystack store file?)");
  } else if (std::memcmp(h.magic, magic, 8) != 0) {
    status = Status::Error(path + ": wrong magic (not a raystack store file of this kind)");
  } else if (h.version != kFormatVersion) {
    status = Status::Error(StrFormat("%s: format version %u, this build reads version %u "
                                     "(convert the model again with raystack-prep)",
                                     path.c_str(), h.version, kFormatVersion));
  } else if (h.header_bytes != sizeof h) {
    status = Status::Error(StrFormat("%s: damaged header (its header size says %u bytes, not %zu)",
                                     path.c_str(), h.header_bytes, sizeof h));
  } else if (h.body_bytes != size - sizeof h) {
    status = SizeMismatch(path, size - sizeof h, h.body_bytes);
  } else {
    body->resize(h.body_bytes);
    // In pieces: one pread returns at most ~2 GiB.
    uint64_t done = 0;
    while (done < body->size()) {
      const ssize_t got = ::pread(fd, body->data() + done, body->size() - done,
                                  static_cast<off_t>(sizeof h + done));
      if (got <= 0) break;
      done += static_cast<uint64_t>(got);
    }
    if (done != body->size())
      status = Status::Error(path + ": short read");
    else if (Checksum(*body) != h.body_checksum)
      status = Status::Error(path + ": checksum mismatch (file is damaged)");
  }
  ::close(fd);
  return status;
}

constexpr float kInf = std::numeric_limits<float>::infinity();

bool FiniteBox(const float lo[3], const float hi[3]) {
  for (int a = 0; a < 3; ++a)
    if (!std::isfinite(lo[a]) || !std::isfinite(hi[a]) || lo[a] > hi[a]) return false;
  return true;
}

}  // namespace

Expected<std::unique_ptr<StoreReader>> StoreReader::Open(const std::string& dir) {
  std::unique_ptr<StoreReader> r(new StoreReader());
  r->dir_ = dir;
  Status s = r->ReadIndex();
  if (s.ok()) s = r->ReadOctree();
  if (s.ok()) s = r->ReadLights();
  if (s.ok()) s = r->OpenBlocks();
  if (!s.ok()) return s;
  return r;
}

StoreReader::~StoreReader() {
  if (blocks_fd_ >= 0) ::close(blocks_fd_);
  if (direct_fd_ >= 0) ::close(direct_fd_);
}

Bounds3f StoreReader::root_cell() const {
  const StoreSummary& s = summary_;
  return {{s.root_lower[0], s.root_lower[1], s.root_lower[2]},
          {s.root_upper[0], s.root_upper[1], s.root_upper[2]}};
}

Bounds3f StoreReader::model_bounds() const {
  const StoreSummary& s = summary_;
  return {{s.model_lower[0], s.model_lower[1], s.model_lower[2]},
          {s.model_upper[0], s.model_upper[1], s.model_upper[2]}};
}

Status StoreReader::ReadIndex() {
  const std::string path = dir_ + "/" + kIndexFile;
  std::vector<uint8_t> body;
  RAYSTACK_RETURN_IF_ERROR(ReadChecked(path, kIndexMagic, &body));
  if (body.size() < sizeof summary_) return Status::Error(path + ": truncated summary");
  std::memcpy(&summary_, body.data(), sizeof summary_);
  const StoreSummary& s = summary_;
  const uint64_t expected = sizeof s + uint64_t{s.material_count} * sizeof(MaterialRecord) +
                            uint64_t{s.block_count} * sizeof(BlockEntry);
  if (expected != body.size())
    return Status::Error(path + ": sizes do not match the block and material counts");
  if (s.codec > kCodecShuffleLz4) return Status::Error(path + ": unknown block codec");
  if (s.max_block_bytes > kMaxBlockBytesCap)
    return Status::Error(StrFormat("%s: block size cap %u is above the format's %u", path.c_str(),
                                   s.max_block_bytes, kMaxBlockBytesCap));
  if (!FiniteBox(s.root_lower, s.root_upper)) return Status::Error(path + ": bad root cell");
  if (!FiniteBox(s.model_lower, s.model_upper)) return Status::Error(path + ": bad model bounds");
  materials_.resize(s.material_count);
  blocks_.resize(s.block_count);
  // (memcpy from or to an empty vector's null data() is undefined even for 0 bytes.)
  if (!materials_.empty())
    std::memcpy(materials_.data(), body.data() + sizeof s,
                materials_.size() * sizeof(MaterialRecord));
  if (!blocks_.empty())
    std::memcpy(blocks_.data(), body.data() + sizeof s + materials_.size() * sizeof(MaterialRecord),
                blocks_.size() * sizeof(BlockEntry));
  for (MaterialRecord& m : materials_) m.name[sizeof m.name - 1] = '\0';
  for (uint32_t i = 0; i < blocks_.size(); ++i) {
    const BlockEntry& e = blocks_[i];
    // Sizes the converter cannot write: a loader would size buffers and the cache by them.
    if (e.raw_bytes < sizeof(BlockHeader) || e.raw_bytes > s.max_block_bytes ||
        e.stored_bytes == 0 || e.stored_bytes > MaxStoredBytes(e.raw_bytes))
      return Status::Error(StrFormat("%s: block %u has sizes out of range (%u stored, %u raw bytes; "
                                     "the store's cap is %u)",
                                     path.c_str(), i, e.stored_bytes, e.raw_bytes,
                                     s.max_block_bytes));
    for (int a = 0; a < 3; ++a)
      if (std::isnan(e.bounds_lower[a]) || std::isnan(e.bounds_upper[a]))
        return Status::Error(StrFormat("%s: block %u has NaN bounds", path.c_str(), i));
  }
  // The summary's totals are the blocks' sums (the writer fills them so): what raystack-info
  // prints and the renderer sizes by must agree with the blocks.
  uint64_t references = 0, raw = 0, stored = 0;
  for (const BlockEntry& e : blocks_) {
    references += e.triangle_count;
    raw += e.raw_bytes;
    stored += e.stored_bytes;
  }
  if (references != s.references || raw != s.raw_bytes || stored != s.stored_bytes)
    return Status::Error(path + ": the summary's totals (references, bytes) are not its blocks' sums");
  return OkStatus();
}

Status StoreReader::ReadLights() {
  const std::string path = dir_ + "/" + kLightsFile;
  if (summary_.lights_checksum == 0) {  // written before lights.bin: any beside it is not its own
    struct stat st {};
    if (::stat(path.c_str(), &st) == 0)
      LOG_WARNING("store", "%s: ignored (index.bin was written without it, by an older "
                  "raystack-prep)", path.c_str());
    return OkStatus();
  }
  std::vector<uint8_t> body;
  RAYSTACK_RETURN_IF_ERROR(ReadChecked(path, kLightsMagic, &body));
  if ((static_cast<uint32_t>(Checksum(body)) | 1u) != summary_.lights_checksum)
    return Status::Error(path + ": not this store's (index.bin names another; a conversion was "
                         "interrupted or mixed): convert the model again");
  if (body.size() % sizeof(EmitterRecord) != 0)
    return Status::Error(path + ": size is not a whole number of emitter records");
  emitters_.resize(body.size() / sizeof(EmitterRecord));
  if (!emitters_.empty()) std::memcpy(emitters_.data(), body.data(), body.size());
  for (size_t i = 0; i < emitters_.size(); ++i) {
    const EmitterRecord& e = emitters_[i];
    bool finite = true;
    for (const auto& corner : e.p)
      for (const float x : corner) finite = finite && std::isfinite(x);
    if (!finite || e.material >= materials_.size() || !EmitsLight(materials_[e.material]) ||
        e.triangle >= summary_.source_triangles ||
        (i > 0 && e.triangle <= emitters_[i - 1].triangle))
      return Status::Error(StrFormat("%s: emitter %zu (triangle %u) is not an emissive triangle "
                                     "of this store (a non-finite corner, a material or id out "
                                     "of range, or ids out of order)", path.c_str(), i,
                                     e.triangle));
  }
  lights_listed_ = true;
  return OkStatus();
}

Status StoreReader::ReadOctree() {
  const std::string path = dir_ + "/" + kOctreeFile;
  std::vector<uint8_t> body;
  RAYSTACK_RETURN_IF_ERROR(ReadChecked(path, kOctreeMagic, &body));
  if (body.size() % sizeof(OctreeNode) != 0 ||
      body.size() / sizeof(OctreeNode) != summary_.octree_node_count)
    return Status::Error(path + ": node count does not match index.bin");
  nodes_.resize(summary_.octree_node_count);
  if (nodes_.empty())
    return summary_.block_count == 0 ? OkStatus() : Status::Error(path + ": no root node");
  std::memcpy(nodes_.data(), body.data(), body.size());

  // One tree, no cycles, bounded depth, each block owned by exactly one leaf.
  // Each block's cell must be its leaf's, computed from the root as every walk computes it:
  // a ray's walk ends early when its hit lies inside the cell of the block it just left
  // (BlockWalk::DoneAfter), so a wrong cell would silently lose closer hits beyond it.
  struct Item { uint32_t node; int depth; Bounds3f cell; };
  std::vector<Item> stack{{0, 1, root_cell()}};
  std::vector<uint8_t> seen(nodes_.size(), 0);
  uint64_t blocks_seen = 0;
  while (!stack.empty()) {
    Item it = stack.back();
    stack.pop_back();
    if (seen[it.node]++) return Status::Error(path + ": octree is not a tree");
    if (it.depth > 32) return Status::Error(path + ": octree deeper than 32 levels");
    const OctreeNode& n = nodes_[it.node];
    if (n.kind == kOctreeInner) {
      if (n.first <= it.node || uint64_t{n.first} + 8 > nodes_.size())
        return Status::Error(StrFormat("%s: node %u has children out of range", path.c_str(),
                                       it.node));
      for (uint32_t c = 0; c < 8; ++c)
        stack.push_back({n.first + c, it.depth + 1, ChildCell(it.cell, static_cast<int>(c))});
    } else if (n.kind == kOctreeLeaf) {
      if (n.count == 0 || uint64_t{n.first} + n.count > blocks_.size())
        return Status::Error(StrFormat("%s: leaf %u has blocks out of range", path.c_str(),
                                       it.node));
      for (uint32_t b = n.first; b < n.first + n.count; ++b) {
        const BlockEntry& e = blocks_[b];
        if (e.octree_leaf != it.node)
          return Status::Error(StrFormat("%s: block %u is not owned by leaf %u", path.c_str(), b,
                                         it.node));
        const float lower[3] = {it.cell.lower.x, it.cell.lower.y, it.cell.lower.z};
        const float upper[3] = {it.cell.upper.x, it.cell.upper.y, it.cell.upper.z};
        if (std::memcmp(e.cell_lower, lower, sizeof lower) != 0 ||
            std::memcmp(e.cell_upper, upper, sizeof upper) != 0)
          return Status::Error(StrFormat("%s: block %u's cell in index.bin is not the cell of "
                                         "its octree leaf %u", path.c_str(), b, it.node));
      }
      blocks_seen += n.count;
    } else if (n.kind != kOctreeEmpty) {
      return Status::Error(StrFormat("%s: node %u has unknown kind", path.c_str(), it.node));
    }
  }
  if (blocks_seen != blocks_.size())
    return Status::Error(path + ": leaves do not cover every block once");
  // A node outside the tree was never checked above (an inner one's children could be
  // anywhere), yet the bounds sweep below and the walks' parent tables visit every node. The
  // writer leaves empty slots there; anything else is refused.
  for (uint32_t i = 0; i < nodes_.size(); ++i)
    if (!seen[i] && nodes_[i].kind != kOctreeEmpty)
      return Status::Error(StrFormat("%s: node %u is outside the tree", path.c_str(), i));
  ComputeNodeBounds();
  return OkStatus();
}

void StoreReader::ComputeNodeBounds() {
  const size_t n = nodes_.size();
  node_bounds_.assign(6 * n, kInf);
  for (size_t i = 3 * n; i < 6 * n; ++i) node_bounds_[i] = -kInf;  // every box empty
  float* lower = node_bounds_.data();
  float* upper = node_bounds_.data() + 3 * n;
  const auto extend = [&](uint32_t node, const float lo[3], const float hi[3]) {
    for (int a = 0; a < 3; ++a) {
      float& l = lower[a * n + node];
      float& u = upper[a * n + node];
      l = std::min(l, lo[a]);
      u = std::max(u, hi[a]);
    }
  };
  // Children come after their parent (checked above), so a backward sweep sees them first.
  for (uint32_t node = static_cast<uint32_t>(n); node-- > 0;) {
    const OctreeNode& o = nodes_[node];
    if (o.kind == kOctreeLeaf) {
      for (uint32_t k = o.first; k < o.first + o.count; ++k)
        extend(node, blocks_[k].bounds_lower, blocks_[k].bounds_upper);
    } else if (o.kind == kOctreeInner) {
      for (uint32_t c = o.first; c < o.first + 8; ++c) {
        const float lo[3] = {lower[c], lower[n + c], lower[2 * n + c]};
        const float hi[3] = {upper[c], upper[n + c], upper[2 * n + c]};
        extend(node, lo, hi);
      }
    }
  }
}

NodeBounds StoreReader::NodeBoundsView() const {
  const size_t n = nodes_.size();
  NodeBounds b;
  for (int a = 0; a < 3; ++a) {
    b.lower[a] = node_bounds_.data() + a * n;
    b.upper[a] = node_bounds_.data() + (3 + a) * n;
  }
  return b;
}

Status StoreReader::OpenBlocks() {
  const std::string path = dir_ + "/" + kBlocksFile;
  struct stat st {};
  RAYSTACK_RETURN_IF_ERROR(OpenStoreFile(path, 0, &blocks_fd_, &st));
  blocks_file_bytes_ = static_cast<uint64_t>(st.st_size);
  FileHeader h{};
  if (::pread(blocks_fd_, &h, sizeof h, 0) != static_cast<ssize_t>(sizeof h) ||
      std::memcmp(h.magic, kBlocksMagic, 8) != 0)
    return Status::Error(path + ": not a raystack block file");
  if (h.version != kFormatVersion)
    return Status::Error(StrFormat("%s: format version %u, this build reads version %u "
                                   "(convert the model again with raystack-prep)",
                                   path.c_str(), h.version, kFormatVersion));
  // (Its body has no checksum, each block has its own: the field is 0; a persona flipped bytes in
  // these fields and --verify said "all blocks OK".)
  if (h.header_bytes != sizeof h || h.body_checksum != 0)
    return Status::Error(StrFormat("%s: damaged header (header size %u, checksum field %llx: "
                                   "expected %zu and 0)", path.c_str(), h.header_bytes,
                                   static_cast<unsigned long long>(h.body_checksum), sizeof h));
  if (h.body_bytes != blocks_file_bytes_ - sizeof h) {
    // The file as long as index.bin's blocks: the header's field is what is wrong (a flipped
    // byte there read as "1099511627776 bytes shorter than its header says (truncated?)").
    if (blocks_file_bytes_ - sizeof h == summary_.stored_bytes)
      return Status::Error(StrFormat("%s: damaged header (its body length says %llu bytes; the "
                                     "file holds the %llu bytes of blocks index.bin lists)",
                                     path.c_str(), static_cast<unsigned long long>(h.body_bytes),
                                     static_cast<unsigned long long>(summary_.stored_bytes)));
    return SizeMismatch(path, blocks_file_bytes_ - sizeof h, h.body_bytes);
  }
  // Blocks lie back to back in id order, as the writer puts them: the loader reads
  // neighbouring ids as one run of bytes and finds each block at its offset from the run's
  // first. An index out of order made it compute a negative run size (store_fuzz found the
  // crash) or would make it read outside its buffer; a gap would make it read (and allocate)
  // the gap's bytes with the run, and a peer that sends a run's blocks back to back would be
  // read at the wrong places. In 64 bits, so a hostile offset cannot wrap.
  uint64_t end = sizeof h;
  for (uint32_t i = 0; i < blocks_.size(); ++i) {
    const BlockEntry& e = blocks_[i];
    if (e.offset > blocks_file_bytes_ || e.stored_bytes > blocks_file_bytes_ - e.offset) {
      // An index.bin of another store beside this blocks.bin read as "truncated?" (a
      // hostile-input review); a cut file was found above (its header's size): the totals differ.
      if (summary_.stored_bytes != h.body_bytes)
        return Status::Error(StrFormat("%s holds %llu bytes of blocks where index.bin lists %llu: "
                                       "the two files are not of one store (a conversion "
                                       "interrupted or mixed): convert the model again",
                                       path.c_str(), static_cast<unsigned long long>(h.body_bytes),
                                       static_cast<unsigned long long>(summary_.stored_bytes)));
      return Status::Error(BlockError(i, "lies outside the file"));
    }
    if (e.offset != end)
      return Status::Error(BlockError(i, StrFormat("%s the block before it or the file header "
                                                   "(blocks lie back to back in id order: this "
                                                   "one at byte %llu)",
                                                   e.offset < end ? "overlaps" : "leaves a gap after",
                                                   static_cast<unsigned long long>(end))));
    end = e.offset + e.stored_bytes;
  }
  if (end != blocks_file_bytes_)
    return Status::Error(StrFormat("%s: %llu bytes after the last block (the index says the "
                                   "blocks end at byte %llu; an index.bin of another store beside "
                                   "it? then convert the model again)", path.c_str(),
                                   static_cast<unsigned long long>(blocks_file_bytes_ - end),
                                   static_cast<unsigned long long>(end)));
  return OkStatus();
}

std::string StoreReader::BlockError(uint32_t id, const std::string& what) const {
  const uint64_t offset = id < blocks_.size() ? blocks_[id].offset : 0;
  return StrFormat("%s/%s: block %u (byte offset %llu): ", dir_.c_str(), kBlocksFile, id,
                   static_cast<unsigned long long>(offset)) +
         what;
}

Status StoreReader::ReadStored(uint32_t id, std::vector<uint8_t>* stored) const {
  if (id >= blocks_.size()) return Status::Error(BlockError(id, "no such block"));
  const BlockEntry& e = blocks_[id];
  stored->resize(e.stored_bytes);
  uint64_t done = 0;
  while (done < e.stored_bytes) {
    ssize_t n = ::pread(blocks_fd_, stored->data() + done, e.stored_bytes - done,
                        static_cast<off_t>(e.offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0)
      return Status::Error(BlockError(id, n < 0 ? std::string("read failed: ") +
                                                      std::strerror(errno)
                                                : std::string("unexpected end of file")));
    done += static_cast<uint64_t>(n);
  }
  return OkStatus();
}

Status StoreReader::CheckRange(uint64_t offset, uint64_t size) const {
  if (offset > blocks_file_bytes_ || size > blocks_file_bytes_ - offset)
    return Status::Error(StrFormat("%s/blocks.bin: read of %llu bytes at offset %llu is past the end",
                                   dir_.c_str(), static_cast<unsigned long long>(size),
                                   static_cast<unsigned long long>(offset)));
  return OkStatus();
}

Status StoreReader::ReadRange(uint64_t offset, uint64_t size, uint8_t* out) const {
  RAYSTACK_RETURN_IF_ERROR(CheckRange(offset, size));
  if (direct_fd_ >= 0) return ReadRangeDirect(offset, size, out);
  uint64_t done = 0;
  while (done < size) {
    ssize_t n = ::pread(blocks_fd_, out + done, size - done, static_cast<off_t>(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0)
      return Status::Error(StrFormat("%s/blocks.bin: read at offset %llu failed: %s", dir_.c_str(),
                                     static_cast<unsigned long long>(offset + done),
                                     n < 0 ? std::strerror(errno) : "unexpected end of file"));
    done += static_cast<uint64_t>(n);
  }
  return OkStatus();
}

Status StoreReader::ReadRangeDirect(uint64_t offset, uint64_t size, uint8_t* out) const {
  // The aligned span around the range is read, and the range copied out of it: a copy the
  // buffered path makes too (from the page cache), without its insertion and reclaim.
  const DirectSpan d = DirectSpanOf(offset, size);
  thread_local DirectBuffer buffer;
  uint8_t* span = buffer.Reserve(d.end - d.begin);
  uint64_t done = 0;
  while (done < d.needed) {
    const ssize_t n = ::pread(direct_fd_, span + done, d.end - d.begin - done,
                              static_cast<off_t>(d.begin + done));
    if (n < 0 && errno == EINTR) continue;
    // A read that stops inside an aligned unit met the end of the file (the next direct read
    // from there would only be refused as unaligned).
    const uint64_t got = n > 0 ? static_cast<uint64_t>(n) : 0;
    if (n <= 0 || (got % kDirectAlign != 0 && done + got < d.needed))
      return Status::Error(StrFormat("%s/%s: direct read at offset %llu failed: %s", dir_.c_str(),
                                     kBlocksFile,
                                     static_cast<unsigned long long>(d.begin + done + got),
                                     n < 0 ? std::strerror(errno) : "unexpected end of file"));
    done += got;
  }
  std::memcpy(out, span + d.skip, size);
  return OkStatus();
}

Status StoreReader::UseDirectReads() {
  if (direct_fd_ >= 0) return OkStatus();
  const std::string path = dir_ + "/" + kBlocksFile;
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_DIRECT);
  if (fd < 0)
    return Status::Error(path + ": cannot open for direct reads (O_DIRECT): " +
                         std::strerror(errno));
  // Some filesystems take the flag at open and refuse the reads (EINVAL): try one.
  DirectBuffer probe;
  if (::pread(fd, probe.Reserve(kDirectAlign), kDirectAlign, 0) < 0) {
    const int error = errno;
    ::close(fd);
    return Status::Error(path + ": its filesystem refuses direct reads (O_DIRECT): " +
                         std::strerror(error));
  }
  direct_fd_ = fd;
  return OkStatus();
}

Expected<BlockView> StoreReader::Decode(uint32_t id, std::span<const uint8_t> stored,
                                        AlignedBuffer* scratch, AlignedBuffer* raw) const {
  if (id >= blocks_.size()) return Status::Error(BlockError(id, "no such block"));
  const BlockEntry& e = blocks_[id];
  if (stored.size() != e.stored_bytes || Checksum(stored) != e.checksum)
    return Status::Error(BlockError(id, "checksum mismatch (the block is damaged)"));
  Status s = DecodeBlock(stored, e.raw_bytes, summary_.codec == kCodecShuffleLz4, scratch, raw);
  if (!s.ok()) return Status::Error(BlockError(id, s.message()));
  Expected<BlockView> view = BlockView::Parse(raw->data(), e.raw_bytes, id);
  if (!view.ok()) return Status::Error(BlockError(id, view.status().message()));
  if (view->triangle_count() != e.triangle_count)
    return Status::Error(BlockError(id, "triangle count differs from the index"));
  // The walks skip this block for rays that miss these bounds: they must be its BVH's.
  const BoxBounds root = view->bounds(), index = BoundsOf(e);
  if (std::memcmp(&root, &index, sizeof root) != 0)
    return Status::Error(BlockError(id, "its BVH's box differs from its bounds in index.bin"));
  // What a block claims that its checksum cannot vouch for (a forged block with checksums made
  // again rendered wrong images with exit 0: a hostile-input review). Cheap next to decoding.
  if (view->triangle_count() > 0) {
    if (view->LargestTriangleId() >= summary_.source_triangles)
      return Status::Error(BlockError(id, StrFormat("triangle id %u is beyond the store's %llu "
                                                    "triangles", view->LargestTriangleId(),
                                                    static_cast<unsigned long long>(summary_.source_triangles))));
    // The header's cell is the index's (which Open checked against the octree), so a block
    // moved whole, cell and all, is found too (the day's second review).
    const Bounds3f cell = view->cell(), box = {{root.lower[0], root.lower[1], root.lower[2]},
                                               {root.upper[0], root.upper[1], root.upper[2]}};
    const Bounds3f listed{{e.cell_lower[0], e.cell_lower[1], e.cell_lower[2]},
                          {e.cell_upper[0], e.cell_upper[1], e.cell_upper[2]}};
    if (std::memcmp(&cell, &listed, sizeof cell) != 0)
      return Status::Error(BlockError(id, "its cell differs from its cell in index.bin"));
    if (!cell.Contains(box))
      return Status::Error(BlockError(id, "its box lies outside its octree cell"));
    if (Intersection(view->VertexBounds(), box).Empty())
      return Status::Error(BlockError(id, "its triangles lie outside its box"));
  }
  return view;
}

Expected<BlockView> StoreReader::Load(uint32_t id, std::vector<uint8_t>* stored,
                                      AlignedBuffer* scratch, AlignedBuffer* raw) const {
  RAYSTACK_RETURN_IF_ERROR(ReadStored(id, stored));
  return Decode(id, *stored, scratch, raw);
}

}  // namespace raystack::store
