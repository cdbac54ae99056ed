#pragma once
// The messages that cross processes (master <-> slaves): plain, versioned, size-checked.
//
// A message is a 16-byte header (magic, protocol version, type, sender rank, payload size)
// followed by its payload: a fixed-size POD for the small messages, or a count and that many
// records for pixel batches. Decoding checks every field against the bytes actually received
// and the rank they came from, so a malformed or hostile message is an error naming its sender
// (and what is wrong), never a crash, a huge allocation or a misread. All fields are
// little-endian, as on every machine this runs on (checked at compile time).

#include <bit>
#include <chrono>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "common/render/sample_result.h"

namespace raystack::wire {

static_assert(std::endian::native == std::endian::little, "the wire format is little-endian");

inline constexpr uint32_t kMagic = 0x4d575352;  // "RSWM"
// 2: tile assignments carry a sample range and a pixel-rank range (progressive passes);
// pixel batches carry the rays traced for them. 3: heartbeats, rank-lost notices, shutdown
// flags (a lost slave costs time, never pixels). 5: a block request carries several runs of
// the owner's blocks (the fetches that queued for the same owner), its answer their bytes;
// frame figures count the runs fetched. 6: frame figures carry the slave's CPU time.
// 8: pixel batches carry the primary-hit layers of sample 0 only, the hit flag in the sample.
// 9: frame figures carry where the ray threads waited (for tiles, for blocks). 10: a slave's
// hello carries what it renders (store, scene, build, block mode), which the master checks.
// 11: frame figures carry the engine's own (rays by type, reads, the cache, T_io, the stack,
// peak RSS), so a job's --stats has per slave what a one-process run's has.
inline constexpr uint16_t kProtocolVersion = 11;
// Largest payload accepted: a pixel batch of this many samples at most.
inline constexpr uint32_t kMaxBatchSamples = 1 << 16;
// How often a slave says it is alive (the master drops one it has not heard from for
// several of these: MasterOptions::lost_after).
inline constexpr std::chrono::milliseconds kHeartbeatInterval{500};

enum class MessageType : uint16_t {
  kHello = 1,    // a slave announces what it renders to the master, before anything else
  kTileRequest,  // a slave thread asks for its next tile
  kTileAssign,   // the master hands out a tile, or says there are no more
  kPixelBatch,   // finished samples
  kFrameDone,    // a slave has finished its part of a frame
  kShutdown,     // the master ends the job
  kError,        // a rank failed: why (text naming the block, file or peer)
  kBlockRequest, // a slave asks a block's owner for runs of its blocks (--blocks rem)
  kBlockData,    // the owner's answer: the runs' stored bytes, or that it failed
  kHeartbeat,    // a slave is alive (every kHeartbeatInterval, whatever else it sends)
  kRankLost,     // the master tells the slaves a rank is gone (its blocks: read from disk)
};
inline constexpr uint16_t kMessageTypeCount = 11;
inline constexpr uint32_t kMaxErrorText = 4096;
const char* MessageTypeName(MessageType type);

struct MessageHeader {
  uint32_t magic;
  uint16_t version;
  uint16_t type;
  uint32_t sender;
  uint32_t payload_bytes;
};
static_assert(sizeof(MessageHeader) == 16);

// What a slave renders, so that the master can refuse a slave whose image would differ from
// the others' (another copy of the store, another scene file, another build) rather than
// merge its pixels into the image.
struct Hello {
  uint32_t ray_threads;
  uint32_t flags;           // kHelloRemoteBlocks
  uint64_t store_checksum;  // its store's index checksum, which holds every block's
  uint64_t scene_checksum;  // what its samples depend on besides the store (cameras, lights...)
  char build[40];           // its BuildId(), nul-padded (cut if longer)
  char host[40];            // its host's name, for messages, nul-padded (cut if longer)
};
inline constexpr uint32_t kHelloRemoteBlocks = 1;  // it fetches blocks from peers (--blocks rem)
// A Hello text field as printable text: up to its first nul, other bytes than printable ASCII
// replaced by '?' (a hostile sender's bytes go into messages).
std::string HelloText(const char (&field)[40]);
// Copies `text` into a Hello text field, cut to 39 bytes, nul-padded.
void SetHelloText(char (&field)[40], const std::string& text);
struct TileRequest {
  uint32_t frame;
  uint32_t thread;  // the slave's ray thread that asks
};
struct TileAssign {
  uint32_t frame;
  uint32_t thread;
  int32_t x0, y0, x1, y1;  // [x0, x1) x [y0, y1); empty when `none`
  uint32_t none;           // 1: no more tiles in this frame
  uint32_t sample_begin;   // the samples [sample_begin, sample_end) of each pixel; sample_end
  uint32_t sample_end;     // 0: all of the scene's spp
  uint16_t rank_begin;     // only the pixels whose priority-matrix rank is in
  uint16_t rank_end;       // [rank_begin, rank_end) (rank_end 0: 256, all)
};
// A slave's figures for one frame (what the master gathers per slave).
struct FrameDone {
  uint32_t frame;
  uint32_t ray_threads;
  uint64_t samples;
  uint64_t rays;
  uint64_t tiles;
  uint64_t blocks_loaded;    // #C, reloads included
  uint64_t blocks_distinct;  // #U
  uint64_t bytes_read;       // from the block source (disk or peers)
  double seconds;            // this slave's render time, from its first tile to its end
  uint64_t bytes_from_peers;  // --blocks rem: block bytes fetched from other slaves
  uint64_t bytes_to_peers;    // --blocks rem: block bytes served to other slaves
  double busy_seconds;        // summed over ray threads: tracing, not waiting (RenderStats)
  uint64_t fetches;           // --blocks rem: requests for blocks sent to their owners
  double fetch_wait_seconds;  // --blocks rem: summed over fetches, request to answer
  uint64_t fetch_runs;        // --blocks rem: the loader's runs those requests carried
  double ray_cpu_seconds;     // CPU time of the ray threads (RenderStats)
  double loader_cpu_seconds;  // CPU time of the loader's threads (RenderStats)
  double process_cpu_seconds;  // CPU time of the whole slave process during the frame
  uint32_t flags;              // kFrameDoneDirectReads
  uint32_t reserved;
  // Summed over ray threads (RenderStats): holding no ray, waiting for a tile (its first
  // included); every ray waiting for the loader.
  double tile_wait_seconds;
  double block_wait_seconds;
  // From the slave starting the frame to its end: minus `seconds`, the wait for its first tile
  // (the master finishing the frame before).
  double engine_seconds;
  // The engine's figures (slave::RenderStats, the same names in --stats).
  uint64_t rays_by_type[4];  // primary, shadow, specular, diffuse
  uint64_t reads;
  uint64_t block_visits;
  double cache_hit_rate;
  double loader_busy_seconds;  // T_io
  uint64_t cache_budget_bytes;
  uint64_t cache_peak_bytes;
  uint64_t evictions;
  uint64_t peak_stack_bytes;
  uint64_t peak_stack_rays;
  uint64_t peak_rss_bytes;
};
inline constexpr uint32_t kFrameDoneDirectReads = 1;  // blocks read past the page cache
struct Shutdown {
  uint32_t reason;  // 0: the job is done
  uint32_t flags;   // kShutdownRankDied: a rank died, so no rank may wait for it at the end
};
inline constexpr uint32_t kShutdownRankDied = 1;
struct Heartbeat {
  uint32_t sequence;  // counts up from 0 (for logs)
  uint32_t flags;     // kHeartbeatInterrupted (the master's)
};
// The master was interrupted (SIGINT, SIGTERM) and is writing its frame: a slave that got the
// signal too waits for the end of the job instead of ending on its own.
inline constexpr uint32_t kHeartbeatInterrupted = 1;
struct RankLost {
  uint32_t rank;
  uint32_t died;  // 1: it went silent (dead: send it nothing more); 0: it failed, alive
};
// A block request is this header and `runs` BlockRun records: the owner answers with the
// runs' stored bytes back to back, in the request's order.
struct BlockRequest {
  uint32_t request;  // the asker's number for it, echoed in the answer
  uint32_t runs;     // BlockRun records that follow, 1..kMaxRequestRuns
  uint32_t reserved[2];
};
struct BlockRun {
  uint32_t first;  // blocks [first, first + count), consecutive in blocks.bin
  uint32_t count;
};
inline constexpr uint32_t kMaxRequestRuns = 256;
struct BlockDataHeader {  // followed by the runs' stored bytes (none when failed)
  uint32_t request;
  uint32_t runs;    // as many as the request had
  uint32_t failed;  // 1: the owner could not read them (its own log says why)
  uint32_t reserved;
};
// A pixel batch is this header, `count` SampleRecords, then `primary` PrimaryRecords: those
// of the first `primary` samples, which are the batch's sample-0 ones (whose hit gives the Z,
// normal and albedo layers). Other samples leave them out: the film
// only keeps sample 0's, and at 8 samples a pixel that is 2.2x fewer bytes.
struct PixelBatchHeader {
  uint32_t frame;
  uint32_t count;    // SampleRecords that follow
  uint64_t rays;     // rays the slave traced for these samples (progress figures)
  uint32_t primary;  // PrimaryRecords after them: samples [0, primary) are sample 0
  uint32_t reserved;
};
struct SampleRecord {
  uint32_t pixel;
  uint32_t sample;  // the sample's index, and kSampleHit when its primary ray hit geometry
  float rgb[3];
};
inline constexpr uint32_t kSampleHit = 1u << 31;
struct PrimaryRecord {
  float z;
  float normal[3];
  float albedo[3];
};
static_assert(sizeof(Hello) == 104 && sizeof(TileRequest) == 8 && sizeof(TileAssign) == 40 &&
              sizeof(FrameDone) == 280 && sizeof(Shutdown) == 8 && sizeof(PixelBatchHeader) == 24 &&
              sizeof(SampleRecord) == 20 && sizeof(PrimaryRecord) == 28 &&
              sizeof(BlockRequest) == 16 && sizeof(BlockRun) == 8 && sizeof(BlockDataHeader) == 16 &&
              sizeof(Heartbeat) == 8 && sizeof(RankLost) == 8);

// Builders: the whole message (header + payload) as bytes.
std::vector<uint8_t> Encode(uint32_t sender, const Hello& m);
std::vector<uint8_t> Encode(uint32_t sender, const TileRequest& m);
std::vector<uint8_t> Encode(uint32_t sender, const TileAssign& m);
std::vector<uint8_t> Encode(uint32_t sender, const FrameDone& m);
std::vector<uint8_t> Encode(uint32_t sender, const Shutdown& m);
std::vector<uint8_t> EncodeBlockRequest(uint32_t sender, uint32_t request,
                                        std::span<const BlockRun> runs);  // 1..kMaxRequestRuns
std::vector<uint8_t> Encode(uint32_t sender, const Heartbeat& m);
std::vector<uint8_t> Encode(uint32_t sender, const RankLost& m);
std::vector<uint8_t> EncodeBlockData(uint32_t sender, const BlockDataHeader& h,
                                     std::span<const uint8_t> stored);
std::vector<uint8_t> EncodeError(uint32_t sender, const std::string& text);  // cut to kMaxErrorText
std::vector<uint8_t> EncodePixelBatch(uint32_t sender, uint32_t frame,
                                      std::span<const render::SampleResult> samples,
                                      uint64_t rays = 0);

// A checked message: the header, and the payload as it arrived (valid while `bytes` is).
struct Message {
  MessageHeader header;
  std::span<const uint8_t> payload;
  MessageType type() const { return static_cast<MessageType>(header.type); }
  // Typed views; call the one that matches type() (checked).
  Hello hello() const;
  TileRequest tile_request() const;
  TileAssign tile_assign() const;
  FrameDone frame_done() const;
  Shutdown shutdown() const;
  PixelBatchHeader batch_header() const;
  std::string error_text() const;
  BlockRequest block_request() const;
  // The request's runs, copied out (the payload need not be aligned for BlockRun).
  void block_runs(std::vector<BlockRun>* out) const;
  Heartbeat heartbeat() const;
  RankLost rank_lost() const;
  BlockDataHeader block_data_header() const;
  std::span<const uint8_t> block_data() const;  // the stored bytes after the header
  // The batch's samples, sample-0 ones first (as encoded). The others come without primary-hit
  // layers: z +inf, normal and albedo 0, which the film does not read for them.
  void batch_samples(std::vector<render::SampleResult>* out) const;
};

// Checks `bytes`, received from rank `from`: magic, version, known type, sizes (the payload's
// against the header's and the type's), sender == from. The error names the sender rank.
Expected<Message> Decode(std::span<const uint8_t> bytes, int from);
// A temporary's bytes would be gone before the message is read (its payload points into them:
// the wire tests did so, found by AddressSanitizer): refused at compile time.
Expected<Message> Decode(std::vector<uint8_t>&& bytes, int from) = delete;
// Whether `bytes` start with a header of this protocol (magic and version): a sender whose
// message fails Decode without one cannot read this build's messages either.
bool SpeaksThisProtocol(std::span<const uint8_t> bytes);

}  // namespace raystack::wire
