#include "master/tile_ledger.h"

#include "common/base/check.h"
#include "common/base/log.h"
#include "common/render/frame_plan.h"

namespace raystack::master {

void TileLedger::Assign(const render::Tile& tile, int rank) {
  const uint64_t samples = (tile.sample_end == 0 ? spp_ : tile.sample_end) - tile.sample_begin;
  const uint64_t bits = static_cast<uint64_t>(tile.pixels()) * samples;
  const uint64_t expected = render::TileSamples(tile, spp_);
  std::vector<render::SampleResult> kept;
  if (!spare_kept_.empty()) {
    kept = std::move(spare_kept_.back());
    spare_kept_.pop_back();
  }
  kept.reserve(expected);  // (the last sample is never kept: the tile then finishes)
  CHECK(rank >= 0);
  if (static_cast<size_t>(rank) >= ranks_.size()) ranks_.resize(static_cast<size_t>(rank) + 1);
  ranks_[static_cast<size_t>(rank)].in_flight.push_back(
      {tile, 0, expected, std::move(kept), std::vector<uint64_t>((bits + 63) / 64, 0)});
  ++unfinished_;
}

size_t TileLedger::SeenBit(const Entry& e, const render::SampleResult& s) const {
  const render::Tile& t = e.tile;
  const uint32_t end = t.sample_end == 0 ? spp_ : t.sample_end;
  const auto x = static_cast<size_t>(s.pixel % static_cast<uint32_t>(width_));
  const auto y = static_cast<size_t>(s.pixel / static_cast<uint32_t>(width_));
  const size_t in_tile = (y - static_cast<size_t>(t.y0)) * static_cast<size_t>(t.x1 - t.x0) +
                         (x - static_cast<size_t>(t.x0));
  return in_tile * (end - t.sample_begin) + (s.sample - t.sample_begin);
}

bool TileLedger::Holds(const render::Tile& t, const render::SampleResult& s) const {
  const int x = static_cast<int>(s.pixel % static_cast<uint32_t>(width_));
  const int y = static_cast<int>(s.pixel / static_cast<uint32_t>(width_));
  const uint32_t end = t.sample_end == 0 ? spp_ : t.sample_end;
  return x >= t.x0 && x < t.x1 && y >= t.y0 && y < t.y1 && s.sample >= t.sample_begin &&
         s.sample < end && t.HasRank(x, y);
}

Status TileLedger::Record(int rank, std::span<const render::SampleResult> samples) {
  if (samples.empty()) return OkStatus();
  if (rank < 0 || static_cast<size_t>(rank) >= ranks_.size())
    return Status::Error(StrFormat("rank %d sent sample %u of pixel %u, which no tile it is "
                                   "rendering holds", rank, samples[0].sample, samples[0].pixel));
  std::vector<Entry>& in_flight = ranks_[static_cast<size_t>(rank)].in_flight;
  size_t& last = ranks_[static_cast<size_t>(rank)].last;
  for (const render::SampleResult& s : samples) {
    size_t i = last;
    if (i >= in_flight.size() || !Holds(in_flight[i].tile, s)) {
      i = 0;
      while (i < in_flight.size() && !Holds(in_flight[i].tile, s)) ++i;
    }
    if (i == in_flight.size())
      return Status::Error(StrFormat("rank %d sent sample %u of pixel %u, which no tile it is "
                                     "rendering holds", rank, s.sample, s.pixel));
    Entry& e = in_flight[i];
    const size_t bit = SeenBit(e, s);
    uint64_t& word = e.seen[bit / 64];
    const uint64_t mask = uint64_t{1} << (bit % 64);
    if (word & mask)
      return Status::Error(StrFormat("rank %d sent sample %u of pixel %u twice", rank, s.sample,
                                     s.pixel));
    word |= mask;
    last = i;
    if (++e.received == e.expected) {  // finished: nothing to take back any more
      e.kept.clear();
      spare_kept_.push_back(std::move(e.kept));
      in_flight[i] = std::move(in_flight.back());
      in_flight.pop_back();
      --unfinished_;
    } else {
      e.kept.push_back(s);
    }
  }
  return OkStatus();
}

std::vector<render::Tile> TileLedger::Release(int rank, std::vector<render::SampleResult>* merged) {
  std::vector<render::Tile> released;
  if (rank < 0 || static_cast<size_t>(rank) >= ranks_.size()) return released;
  RankTiles& r = ranks_[static_cast<size_t>(rank)];
  for (Entry& e : r.in_flight) {
    merged->insert(merged->end(), e.kept.begin(), e.kept.end());
    released.push_back(e.tile);
    --unfinished_;
  }
  r.in_flight.clear();
  r.last = 0;
  return released;
}

}  // namespace raystack::master
