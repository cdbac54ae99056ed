#pragma once
// The on-disk block store, version 2. FORMAT.md beside this file is the prose spec; this header
// is its exact layout. All integers and floats are little-endian; every struct is a POD whose
// size is pinned by a static_assert so a change of layout is a compile error.
//
// A store is a directory with four files:
//   index.bin   FileHeader + StoreSummary + MaterialRecord[material_count] + BlockEntry[block_count]
//   octree.bin  FileHeader + OctreeNode[node_count]        (the level-1 octree, always in RAM)
//   blocks.bin  FileHeader + stored blocks at BlockEntry::offset
//   lights.bin  FileHeader + EmitterRecord[n]                (the emissive triangles, FORMAT.md)
// Each stored block is lz4( byte_shuffle( raw block ) ); a raw block is BlockHeader followed by
// the sections of BlockLayout (block_layout.h).

#include <cstdint>

namespace raystack::store {

inline constexpr uint32_t kFormatVersion = 2;  // 2: BlockEntry holds the block's bounds
inline constexpr char kIndexMagic[8] = {'R', 'S', 'T', 'K', 'I', 'D', 'X', '\0'};
inline constexpr char kOctreeMagic[8] = {'R', 'S', 'T', 'K', 'O', 'C', 'T', '\0'};
inline constexpr char kBlocksMagic[8] = {'R', 'S', 'T', 'K', 'B', 'L', 'K', '\0'};
inline constexpr const char* kIndexFile = "index.bin";
inline constexpr const char* kOctreeFile = "octree.bin";
inline constexpr const char* kBlocksFile = "blocks.bin";
// The emissive triangles (optional: stores written before it have none, see EmitterRecord).
inline constexpr char kLightsMagic[8] = {'R', 'S', 'T', 'K', 'L', 'I', 'T', '\0'};
inline constexpr const char* kLightsFile = "lights.bin";
// Empty; locked by the converter while it writes the store (not part of the format).
inline constexpr const char* kLockFile = ".lock";

// Heads each of the four files. The body checksum covers everything after the header (for
// blocks.bin it is 0: each block carries its own checksum in its BlockEntry).
struct FileHeader {
  char magic[8];
  uint32_t version;
  uint32_t header_bytes;  // sizeof(FileHeader), so a reader can tell a foreign layout
  uint64_t body_bytes;
  uint64_t body_checksum;  // XXH3-64 of the body
};
static_assert(sizeof(FileHeader) == 32);

// What the model has; a block stores an attribute only if the model (and the block) has it.
enum ModelFlags : uint32_t {
  kModelHasNormals = 1u << 0,
  kModelHasUvs = 1u << 1,
  kModelHasMaterials = 1u << 2,
  // Emissive triangles exist but lights.bin lists none: more than the converter's budget held.
  kModelEmittersUnlisted = 1u << 3,
};

struct StoreSummary {
  uint64_t source_triangles;  // triangles given to the store (after dropping zero-area ones)
  uint64_t references;        // sum of block triangle counts (>= source_triangles: clipping)
  uint64_t raw_bytes;         // sum of raw block sizes
  uint64_t stored_bytes;      // sum of stored (compressed) block sizes
  uint32_t block_count;
  uint32_t octree_node_count;
  uint32_t material_count;
  uint32_t model_flags;        // ModelFlags
  float model_lower[3], model_upper[3];  // bounds of all triangles
  float root_lower[3], root_upper[3];    // the level-1 octree's root cell (a cube)
  uint32_t max_block_bytes;     // the cap the store was built with
  uint32_t target_block_bytes;  // the mean it aimed at
  uint32_t codec;               // BlockCodec
  // lights.bin's body checksum, its low 32 bits | 1; 0 in a store written before lights.bin
  // (whose reader then ignores a lights.bin beside it: another conversion's).
  uint32_t lights_checksum;
};
static_assert(sizeof(StoreSummary) == 112);

// The largest block cap (StoreSummary::max_block_bytes) the converter accepts: 1 GiB.
inline constexpr uint32_t kMaxBlockBytesCap = 1u << 30;

enum BlockCodec : uint32_t { kCodecLz4 = 0, kCodecShuffleLz4 = 1 };

struct MaterialRecord {
  char name[64];  // NUL-terminated, truncated to 63 bytes
  float kd[3], ks[3], ke[3];
  float ni, d;
  int32_t illum;
};
static_assert(sizeof(MaterialRecord) == 112);

// lights.bin's body: every triangle whose material emits (Ke > 0 in its MTL), once each (not
// per block), in source id order, so that a path tracer can aim rays at the emitters without
// reading the blocks that hold them (next-event estimation).
struct EmitterRecord {
  float p[3][3];      // the corners, as in the blocks
  uint32_t triangle;  // source triangle id
  uint32_t material;  // index into index.bin's materials
};
static_assert(sizeof(EmitterRecord) == 44);

// True when an MTL record emits (what MaterialFromMtl makes emissive; the converter lists its
// triangles in lights.bin).
inline bool EmitsLight(const MaterialRecord& m) {
  for (const float k : m.ke)
    if (k > 0 && k <= 3.402823466e38f) return true;  // finite and positive (NaN compares false)
  return false;
}

struct BlockEntry {
  uint64_t offset;        // in blocks.bin
  uint32_t stored_bytes;  // compressed size on disk
  uint32_t raw_bytes;     // size after decompression
  float cell_lower[3], cell_upper[3];  // the octree leaf cell the block's triangles are clipped to
  // The box of the block's BVH root node (its triangles' bounds clipped to the cell), bit for
  // bit: a ray that misses it within its interval meets nothing in the block, so the walks skip
  // the block without loading it. Checked against the BVH when the block is decoded.
  float bounds_lower[3], bounds_upper[3];
  uint32_t triangle_count;
  uint32_t octree_leaf;  // node index of its leaf in octree.bin
  uint64_t checksum;     // XXH3-64 of the stored bytes
};
static_assert(sizeof(BlockEntry) == 80);

// Level-1 octree node. Children of an inner node are 8 consecutive nodes starting at `first`,
// in Morton order (bit 0 = +x half, bit 1 = +y, bit 2 = +z). A leaf's blocks are
// [first, first + count); most leaves have one block, a leaf whose triangles cannot be
// separated spatially (all at one point) has several.
struct OctreeNode {
  uint32_t first;
  uint16_t count;
  uint8_t kind;  // OctreeNodeKind
  uint8_t pad;
};
static_assert(sizeof(OctreeNode) == 8);
enum OctreeNodeKind : uint8_t { kOctreeEmpty = 0, kOctreeLeaf = 1, kOctreeInner = 2 };

// Material index meaning "none" (24 bits in the converter, 16 bits in per-triangle sections).
inline constexpr uint32_t kNoMaterial = 0x00ffffffu;
inline constexpr uint16_t kNoMaterial16 = 0xffffu;
inline constexpr uint32_t kMaxMaterials = 0xfffeu;
// Triangle ids are 32-bit and 0xffffffff means none: at most this many triangles in a store.
inline constexpr uint64_t kMaxTriangles = 0xfffffffeull;  // 4,294,967,294

// Raw block header; followed by the sections described in block_layout.h.
inline constexpr uint32_t kBlockMagic = 0x4b425352u;  // "RSBK"
enum BlockFlags : uint16_t {
  kBlockIndices32 = 1u << 0,            // u32 vertex indices (else u16)
  kBlockPerTriangleMaterial = 1u << 1,  // u16 material per triangle (else constant_material)
  kBlockNormals = 1u << 2,              // per-vertex normals section
  kBlockUvs = 1u << 3,                  // per-vertex uv section
};
struct BlockHeader {
  uint32_t magic;
  uint16_t version;
  uint16_t flags;  // BlockFlags
  uint32_t vertex_count;
  uint32_t triangle_count;
  uint32_t node_count;
  uint32_t constant_material;  // material of every triangle when not per-triangle (kNoMaterial = none)
  uint32_t reserved[4];        // zero. (No block id here: the index's checksum ties bytes to ids.)
  float cell_lower[3], cell_upper[3];
};
static_assert(sizeof(BlockHeader) == 64, "sections start 16-byte aligned after the header");

}  // namespace raystack::store
