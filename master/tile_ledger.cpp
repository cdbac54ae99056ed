#include "master/tile_ledger.h"

#include "common/base/check.h"
#include "common/base/log.h"

namespace raystack::master {

TileLedger::TileLedger(const std::vector<render::Tile>& tiles, int width, int height,
                       uint32_t spp)
    : entries_(tiles.size()),
      tile_of_pixel_(static_cast<size_t>(width) * static_cast<size_t>(height), 0),
      spp_(spp),
      unfinished_(tiles.size()) {
  for (size_t i = 0; i < tiles.size(); ++i) {
    const render::Tile& t = tiles[i];
    entries_[i].expected = static_cast<uint64_t>(t.pixels()) * spp;
    for (int y = t.y0; y < t.y1; ++y)
      for (int x = t.x0; x < t.x1; ++x)
        tile_of_pixel_[static_cast<size_t>(y) * static_cast<size_t>(width) +
                       static_cast<size_t>(x)] = static_cast<uint32_t>(i);
  }
}

void TileLedger::Assign(size_t index, int rank) {
  Entry& e = entries_[index];
  CHECK(e.rank == kNobody && e.received < e.expected);
  e.rank = rank;
}

Status TileLedger::Record(int rank, std::span<const render::SampleResult> samples) {
  for (const render::SampleResult& s : samples) {
    if (s.pixel >= tile_of_pixel_.size() || s.sample >= spp_)
      return Status::Error(StrFormat("rank %d sent sample %u of pixel %u, which the image does "
                                     "not have", rank, s.sample, s.pixel));
    Entry& e = entries_[tile_of_pixel_[s.pixel]];
    if (e.rank != rank || e.received == e.expected)
      return Status::Error(StrFormat("rank %d sent a sample of pixel %u, in a tile it is not "
                                     "rendering", rank, s.pixel));
    if (++e.received == e.expected) {
      e.kept = {};  // finished: nothing to take back any more
      e.rank = kNobody;
      --unfinished_;
    } else {
      e.kept.push_back(s);
    }
  }
  return OkStatus();
}

std::vector<size_t> TileLedger::Release(int rank, std::vector<render::SampleResult>* merged) {
  std::vector<size_t> released;
  for (size_t i = 0; i < entries_.size(); ++i) {
    Entry& e = entries_[i];
    if (e.rank != rank) continue;
    merged->insert(merged->end(), e.kept.begin(), e.kept.end());
    e = Entry{kNobody, 0, e.expected, {}};
    released.push_back(i);
  }
  return released;
}

std::vector<size_t> TileLedger::InFlight(int rank) const {
  std::vector<size_t> out;
  for (size_t i = 0; i < entries_.size(); ++i)
    if (entries_[i].rank == rank) out.push_back(i);
  return out;
}

}  // namespace raystack::master
