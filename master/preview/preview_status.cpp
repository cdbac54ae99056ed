#include "master/preview/preview_status.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/base/log.h"
#include "common/base/utf8.h"

namespace raystack::master::preview {
namespace {

constexpr double kUnknown = std::numeric_limits<double>::quiet_NaN();

// JSON has no NaN: unknown figures are null, which the page shows as "—".
std::string Number(double v) { return std::isfinite(v) ? StrFormat("%.6g", v) : "null"; }

// A JSON string: quotes, backslashes and control characters escaped, bytes that are not UTF-8
// as '?'.
std::string Quoted(const std::string& text) {
  std::string out = "\"";
  for (size_t i = 0; i < text.size();) {
    const auto c = static_cast<unsigned char>(text[i]);
    const size_t n = Utf8Length(text, i);
    if (n == 0) {
      out += '?';
      ++i;
      continue;
    }
    if (c == '"' || c == '\\') out += '\\';
    if (c < 0x20)
      out += StrFormat("\\u%04x", c);
    else
      out.append(text, i, n);
    i += n;
  }
  return out + "\"";
}

// A tile is done when each of its pixels (those of its ranks: a coarse round's tile has a few
// of its rectangle's) has the samples the tile brings it to: its pass's end, not the frame's
// spp, or every tile of a progressive render would stay "in flight" until the last pass.
bool TileDone(const render::Tile& t, int width, const std::vector<uint32_t>& counts, int spp) {
  const uint32_t target = t.sample_end > 0 ? t.sample_end : static_cast<uint32_t>(spp);
  for (int y = t.y0; y < t.y1; ++y)
    for (int x = t.x0; x < t.x1; ++x) {
      if (!t.HasRank(x, y)) continue;
      const size_t i = static_cast<size_t>(y) * static_cast<size_t>(width) + static_cast<size_t>(x);
      if (i >= counts.size() || counts[i] < target) return false;
    }
  return true;
}

}  // namespace

std::string StatusJson(const PreviewStatus& s, int width, const std::vector<uint32_t>& counts) {
  const uint64_t done = s.samples_done + s.samples_restored;
  const double progress =
      s.samples_total > 0 ? static_cast<double>(std::min(done, s.samples_total)) / static_cast<double>(s.samples_total) : 0.0;
  const double per_second = s.elapsed_seconds > 0 ? static_cast<double>(s.samples_done) / s.elapsed_seconds : kUnknown;
  // Time left at the mean rate so far; unknown until the first samples are in.
  const double left = s.finished ? 0.0
                      : s.failed || s.interrupted ? kUnknown
                      : s.samples_done > 0 && per_second > 0
                          ? static_cast<double>(s.samples_total - std::min(done, s.samples_total)) / per_second
                          : kUnknown;
  std::string json = StrFormat(
      "{\"type\":\"status\",\"frame\":%u,\"frames\":%u,\"last_frame\":%u,\"samples_done\":%llu,"
      "\"samples_total\":%llu,"
      "\"progress\":%s,\"elapsed_seconds\":%s,\"samples_per_second\":%s,\"rays_per_second\":%s,"
      "\"seconds_left\":%s,\"error_estimate\":%s,\"finished\":%s,\"failed\":%s,\"interrupted\":%s,"
      "\"note\":%s,\"tiles\":[",
      s.frame, s.frames, s.last_frame, static_cast<unsigned long long>(s.samples_done),
      static_cast<unsigned long long>(s.samples_total), Number(progress).c_str(),
      Number(s.elapsed_seconds).c_str(), Number(per_second).c_str(),
      Number(s.rays_per_second).c_str(), Number(left).c_str(), Number(s.error_estimate).c_str(),
      s.finished ? "true" : "false", s.failed ? "true" : "false", s.interrupted ? "true" : "false",
      Quoted(s.note).c_str());
  bool first_rank = true;
  for (const RankTiles& r : s.tiles) {
    json += StrFormat("%s{\"rank\":%d,\"dropped\":%s,\"tiles\":[", first_rank ? "" : ",", r.rank,
                      Quoted(r.dropped).c_str());
    first_rank = false;
    bool first = true;
    for (const render::Tile& t : r.tiles) {
      const bool over = s.finished || s.failed || s.interrupted;
      if (over || (!counts.empty() && TileDone(t, width, counts, s.spp))) continue;
      json += StrFormat("%s[%d,%d,%d,%d]", first ? "" : ",", t.x0, t.y0, t.x1, t.y1);
      first = false;
    }
    json += "]}";
  }
  return json + "]}";
}

}  // namespace raystack::master::preview
