#include "master/resume.h"

#include <sys/stat.h>

#include <algorithm>

#include "common/base/log.h"
#include "common/image/exr_io.h"

namespace raystack::master {
namespace {

// The first line where two provenance records differ ("build ...", "store ...", "camera ...",
// ...), as "checkpoint: LINE; this run: LINE", each cut to a readable length.
// The record without its "build ..." line.
std::string WithoutBuild(const std::string& record) {
  const size_t at = record.find("\nbuild ");
  if (at == std::string::npos) return record;
  const size_t end = record.find('\n', at + 1);
  return record.substr(0, at) + (end == std::string::npos ? std::string() : record.substr(end));
}

std::string FirstDifference(const std::string& theirs, const std::string& ours, const char* what) {
  size_t a = 0, b = 0;
  auto line = [](const std::string& text, size_t at) {
    if (at >= text.size()) return std::string();
    const size_t end = text.find('\n', at);
    std::string l = text.substr(at, end == std::string::npos ? std::string::npos : end - at);
    return l.size() > 120 ? l.substr(0, 117) + "..." : l;
  };
  // Line by line; a record that ends before the other (with or without its last newline)
  // differs at the other's next line, shown against "".
  while (a < theirs.size() || b < ours.size()) {
    const size_t ea = std::min(theirs.find('\n', a), theirs.size());
    const size_t eb = std::min(ours.find('\n', b), ours.size());
    if (theirs.compare(a, ea - a, ours, b, eb - b) != 0)
      return std::string(what) + ": '" + line(theirs, a) + "'; this run: '" + line(ours, b) + "'";
    a = std::min(ea + 1, theirs.size());
    b = std::min(eb + 1, ours.size());
  }
  return "their records differ";
}

}  // namespace


bool ResumePlan::Needs(const render::Tile& t) const {
  if (finished.empty()) return true;
  for (int y = t.y0; y < t.y1; ++y)
    for (int x = t.x0; x < t.x1; ++x) {
      if (t.HasRank(x, y) &&
          !finished[static_cast<size_t>(y) * static_cast<size_t>(width) + static_cast<size_t>(x)])
        return true;
    }
  return false;
}

size_t DropFinishedTiles(const ResumePlan& resume, render::FramePlan* plan) {
  // (Not the checkpoint: the plan keeps a bit a tile, not `resume`, ~52 bytes a pixel.)
  if (!resume.finished.empty()) plan->Keep([&](const render::Tile& t) { return resume.Needs(t); });
  size_t tiles = 0;
  for (const render::Sweep& sweep : plan->sweeps) tiles += sweep.tile_count;
  return tiles;
}

Expected<ResumePlan> PlanResume(const std::string& exr, int width, int height, uint32_t spp,
                                const std::string& provenance) {
  ResumePlan plan;
  plan.width = width;
  struct stat st;
  if (stat(exr.c_str(), &st) != 0) return plan;
  Expected<image::ImageLayers> read = image::ReadExr(exr);
  if (!read.ok())
    return Status::Error(read.status().message() + ": cannot resume from it; give another "
                         "--output, or move it aside to render the frame from the start");
  if (read->width != width || read->height != height)
    return Status::Error(StrFormat("%s: the checkpoint is %dx%d, this frame %dx%d: not a "
                                   "checkpoint of this frame; give another --output, or remove it "
                                   "to render from the start", exr.c_str(), read->width,
                                   read->height, width, height));
  // A complete frame rendered by another build of the same scene is kept as it is, as every
  // complete frame is (found by an operator: a job requeued after a rebuild was refused on its
  // finished frames); a checkpoint is continued by its own build only, whose pixels match.
  const bool complete =
      !read->partial && !read->samples.empty() &&
      std::all_of(read->samples.begin(), read->samples.end(), [&](auto n) { return n >= spp; });
  const bool kept_from_another_build = complete && !read->provenance.empty() &&
                                       read->provenance != provenance &&
                                       WithoutBuild(read->provenance) == WithoutBuild(provenance);
  if (read->provenance != provenance && !kept_from_another_build)
    return Status::Error(
        exr + (read->provenance.empty()
                   ? ": it does not say what rendered it (not a raystack checkpoint of this "
                     "version): cannot resume from it"
                   : ": rendered from another scene, camera, setting or build (" +
                         FirstDifference(read->provenance, provenance,
                                         read->partial ? "checkpoint" : "the frame") +
                         "): give another --output, or remove it to render from the start (its "
                         "pixels are lost)"));
  if (read->samples.empty())
    return Status::Error(exr + ": no per-pixel sample counts (samples layer): not a raystack "
                         "checkpoint, cannot resume from it");
  plan.finished.assign(read->samples.size(), 0);
  for (size_t i = 0; i < read->samples.size(); ++i)
    if (read->samples[i] >= spp) {
      plan.finished[i] = 1;
      plan.kept_pixels.push_back(static_cast<uint32_t>(i));
    }
  plan.checkpoint = std::move(*read);
  return plan;
}

}  // namespace raystack::master
