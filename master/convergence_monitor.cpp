#include "master/convergence_monitor.h"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>

#include "common/base/file_lock.h"
#include "common/base/log.h"
#include "common/base/output_target.h"

namespace raystack::master {

namespace {

// A file (or none yet) is opened locked, then emptied: two jobs' rows in one log made it
// unreadable (raystack-plot: "3 fields, expected 12"; a pipeline review). The lock is the log's
// own, so a writable log in a folder the job cannot write still works. -1 and *error if not.
int OpenLockedFile(const std::string& path, std::string* error) {
  int fd = -1;
  switch (TryLockFile(path, /*create=*/true, &fd, error, {}, 0666)) {
    case LockResult::kLocked:
      break;
    case LockResult::kNoLocks:
      LOG_WARNING("render", "%s: its filesystem takes no file locks: nothing keeps another "
                  "render from writing this convergence log at once", path.c_str());
      break;
    case LockResult::kHeldElsewhere:
      *error = "another raystack render is writing this log now; wait for it, or give another "
               "--convergence-log";
      return -1;
    case LockResult::kNoFile:
    case LockResult::kError: {  // "PATH: cannot open: why": the why (the caller names the path)
      const size_t at = error->rfind(": ");
      if (at != std::string::npos) *error = error->substr(at + 2);
      return -1;
    }
  }
  if (::ftruncate(fd, 0) != 0) {
    *error = std::strerror(errno);
    ::close(fd);
    return -1;
  }
  return fd;
}

}  // namespace

Expected<std::unique_ptr<ConvergenceLog>> ConvergenceLog::Open(const std::string& path) {
  // A stream (a pipe, a terminal, the standard output even when that is a file, which a locked
  // open would have emptied) is the job's own; a file is locked.
  const OutputTarget target = ResolveOutputTarget(path);
  std::string error;
  const int fd = target.stream ? OpenStream(target, &error) : OpenLockedFile(target.path, &error);
  if (fd < 0)
    return Status::Error(StrFormat("%s: cannot write the convergence log: %s", path.c_str(),
                                   error.c_str()));
  std::FILE* f = ::fdopen(fd, "w");
  if (!f) {
    const Status failed = Status::Error(StrFormat("%s: cannot write the convergence log: %s",
                                                  path.c_str(), std::strerror(errno)));
    ::close(fd);
    return failed;
  }
  auto log = std::unique_ptr<ConvergenceLog>(new ConvergenceLog(f, path));
  std::fputs("frame,event,pass,seconds,rays,samples,pixels_covered,min_samples,error_estimate,"
             "rel_error_estimate,rmse,relmse\n", f);
  return log;
}

ConvergenceLog::~ConvergenceLog() {
  if (file_) std::fclose(file_);
}

Status ConvergenceLog::Close() {
  if (file_ && std::fclose(file_) != 0 && failed_.ok())
    failed_ = Status::Error(StrFormat("%s: cannot write the convergence log: %s", path_.c_str(),
                                      std::strerror(errno)));
  file_ = nullptr;
  return failed_;
}

void ConvergenceLog::Write(uint32_t frame, const char* event, uint32_t pass,
                           const render::ConvergencePoint& p) {
  auto number = [](double v) { return std::isfinite(v) ? StrFormat("%.9g", v) : std::string(); };
  std::fprintf(file_, "%u,%s,%u,%.6f,%llu,%llu,%llu,%u,%s,%s,%s,%s\n", frame, event, pass,
               p.seconds, static_cast<unsigned long long>(p.rays),
               static_cast<unsigned long long>(p.samples),
               static_cast<unsigned long long>(p.pixels_covered), p.min_samples,
               number(p.error_estimate).c_str(), number(p.rel_error_estimate).c_str(),
               number(p.rmse).c_str(), number(p.relmse).c_str());
  // A reader (or a crash) sees every row written so far. A failed write (a full disk) was
  // silent, the job ending with 0 and the rows lost (a hostile-input review's /dev/full).
  if (std::fflush(file_) != 0 && failed_.ok()) {
    failed_ = Status::Error(StrFormat("%s: cannot write the convergence log: %s; its rows since "
                                      "are lost", path_.c_str(), std::strerror(errno)));
    LOG_WARNING("render", "%s (the render goes on)", failed_.message().c_str());
  }
}

ConvergenceMonitor::ConvergenceMonitor(const render::Film& film, const render::FramePlan& plan,
                                       StopRules rules, uint32_t frame, ConvergenceLog* log,
                                       const image::ImageLayers* reference,
                                       double log_interval_s)
    : film_(film),
      plan_(plan),
      rules_(rules),
      frame_(frame),
      log_(log),
      reference_(reference),
      log_interval_s_(log_interval_s),
      pass_samples_(plan.passes.size(), 0) {
  for (size_t i = 0; i < plan.sweeps.size(); ++i) {
    const render::Sweep& sweep = plan.sweeps[i];
    if (sweep.sample_end > 0 && sweep.pass < plan.passes.size() &&
        sweep.sample_begin >= plan.passes[sweep.pass].begin &&
        sweep.sample_end <= plan.passes[sweep.pass].end) {
      // Every tile's samples lie in the sweep's pass: counted whole from that pass on (a plan's
      // sweeps are not walked tile by tile: it may have tens of millions).
      for (size_t p = sweep.pass; p < plan.passes.size(); ++p) pass_samples_[p] += sweep.samples;
      continue;
    }
    plan.ForEachTile(i, [&](const render::Tile& tile) {
      const uint32_t tile_end = tile.sample_end == 0 ? plan.spp() : tile.sample_end;
      for (size_t p = 0; p < plan.passes.size(); ++p) {
        render::Tile below = tile;  // its samples below the pass's end
        below.sample_end = std::min(tile_end, plan.passes[p].end);
        if (below.sample_begin < below.sample_end) pass_samples_[p] += render::TileSamples(below, plan.spp());
      }
    });
  }
  // Where every curve starts: nothing rendered yet (against a reference, a black image).
  if (log_) log_->Write(frame_, "start", 0, Measure());
}

render::ConvergencePoint ConvergenceMonitor::Measure(const image::ImageLayers* resolved, bool written) const {
  // Counts first, so they never run ahead of the image they describe.
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  const uint64_t rays = film_.rays_traced(), samples = film_.samples_merged();
  // The image changes only as samples merge. A frame's end measures right after its last pass
  // end, and a resolve of a 1024x768 film with the error sums is ~0.1 s: not twice.
  if (!measured_ || measured_samples_ != samples || measured_written_ != written) {
    error_ = {};
    if (resolved) {
      render::EstimateError(*resolved, reference_, &error_, &luminance_, !written);
    } else {
      film_.ResolveInto(&resolved_);
      render::EstimateError(resolved_, reference_, &error_, &luminance_, !written);
    }
    measured_ = true;
    measured_samples_ = samples;
    measured_written_ = written;
  }
  render::ConvergencePoint p = error_;  // the error figures, with this moment's counts
  p.seconds = seconds;
  p.rays = rays;
  p.samples = samples;
  return p;
}

void ConvergenceMonitor::CheckPassEnds(const image::ImageLayers* resolved) {
  if (stopped()) return;
  // Every pass that has ended since the last look (several, when passes are short): the film
  // measured now is the newest's, so the stop rule judges that one, named as such.
  size_t ended = passes_ended_;
  while (ended < plan_.passes.size()) {
    // The last pass ends with the frame: Finish measures it on the image resolved for the
    // EXR. Measured here, the film would be resolved twice at the end of every frame (~20 ms
    // for 960x540, inside the frame's time: 4% of a frame at 8 slaves).
    if (!resolved && ended + 1 == plan_.passes.size()) break;
    if (film_.samples_below(plan_.passes[ended].end) < pass_samples_[ended]) break;
    ++ended;
  }
  if (ended == passes_ended_) return;
  last_ = Measure(resolved);
  while (passes_ended_ < ended) {
    ++passes_ended_;
    if (log_) log_->Write(frame_, "pass", passes_ended_, last_);
  }
  if (rules_.target_error > 0 && last_.min_samples >= 2 &&
      last_.error_estimate <= rules_.target_error && passes_ended_ < plan_.passes.size()) {
    stop_reason_ = StrFormat("--target-error %g reached after pass %u (%u samples per pixel; the "
                             "fewest a pixel has: %u; estimated error %g)", rules_.target_error,
                             passes_ended_, plan_.passes[passes_ended_ - 1].end,
                             last_.min_samples, last_.error_estimate);
    if (log_) log_->Write(frame_, "stop", passes_ended_, last_);
  }
}

bool ConvergenceMonitor::Poll() {
  if (stopped()) return false;
  CheckPassEnds();
  if (stopped()) return false;
  const double now =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  if (rules_.time_limit_s > 0 && now >= rules_.time_limit_s) {
    last_ = Measure();
    // The tiles in flight are finished after it: Finish says the frame's final count (an
    // operator read this count in the stop line and a higher one in the frame's).
    time_stop_samples_ = last_.samples;
    stop_reason_ = StrFormat("--time-limit %g s reached with %llu of %llu samples merged",
                             rules_.time_limit_s, static_cast<unsigned long long>(last_.samples),
                             static_cast<unsigned long long>(plan_.total_samples()));
    if (log_) log_->Write(frame_, "stop", passes_ended_, last_);
    return false;
  }
  if (log_ && now - last_log_s_ >= log_interval_s_) {
    last_log_s_ = now;
    log_->Write(frame_, "tick", passes_ended_, Measure());
  }
  return true;
}

void ConvergenceMonitor::Finish(const image::ImageLayers& resolved) {
  CheckPassEnds(&resolved);
  // The end row is the image as written: a frame stopped before its first pass covered it has
  // black pixels where the rows before showed their ancestors' values (a researcher's 0.64
  // logged against 0.95 for the file).
  // (Only then: with every pixel sampled, or no reference, the two are one; a review.)
  const bool gaps = reference_ && film_.pixels_covered() <
                                      static_cast<uint64_t>(film_.width()) * static_cast<uint64_t>(film_.height());
  last_ = Measure(&resolved, /*written=*/gaps);
  if (time_stop_samples_ && last_.samples != *time_stop_samples_)
    stop_reason_ = StrFormat("--time-limit %g s reached with %llu of %llu samples merged, %llu "
                             "once the tiles then in flight were finished", rules_.time_limit_s,
                             static_cast<unsigned long long>(*time_stop_samples_),
                             static_cast<unsigned long long>(plan_.total_samples()),
                             static_cast<unsigned long long>(last_.samples));
  if (log_) log_->Write(frame_, "end", passes_ended_, last_);
}

}  // namespace raystack::master
