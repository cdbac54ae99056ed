#pragma once
// Watches a progressive frame while it renders (one process, or the master): writes the
// convergence log, and applies the stop rules. The renderer asks it a few times a second
// whether to keep handing out work.
//
// The log is CSV, one header line, then one row per event:
//   frame,event,pass,seconds,rays,samples,pixels_covered,min_samples,error_estimate,
//   rel_error_estimate,rmse,relmse
// event: "start" (the frame's clock starts, nothing merged), "tick" (every --log-interval
// seconds), "pass" (a pass has ended: every pixel has
// its samples up to the pass's end; `pass` counts the passes ended), "stop" (a stop rule
// fired), "end" (the frame's last sample is merged). Figures as in common/render/convergence.h;
// an empty field is a figure not known (no pixel has 2 samples yet; no --reference).

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "common/image/image_layers.h"
#include "common/render/convergence.h"
#include "common/render/film.h"
#include "common/render/frame_plan.h"

namespace raystack::master {

struct StopRules {
  double time_limit_s = 0;   // 0: none. Stop handing out work after this long
  double target_error = 0;   // 0: none. Stop after the first pass whose error_estimate <= this
};

// The CSV file (one for every frame of a job). Not thread-safe: the monitor's thread writes.
class ConvergenceLog {
 public:
  // A pipe (a FIFO another program reads) is fine; one that no program reads is an error now,
  // not a job held in open() until one does. A file is locked for the job (held by the open
  // log): another job writing it is an error.
  static Expected<std::unique_ptr<ConvergenceLog>> Open(const std::string& path);
  ~ConvergenceLog();
  // A row; a failed write (a full disk) is said at once, once, and kept for Close.
  void Write(uint32_t frame, const char* event, uint32_t pass, const render::ConvergencePoint& p);
  // The first failed write, if any (rows lost: the job ends with it, after its images).
  Status Close();

 private:
  ConvergenceLog(std::FILE* f, std::string path) : file_(f), path_(std::move(path)) {}
  std::FILE* file_;
  std::string path_;
  Status failed_;
};

class ConvergenceMonitor {
 public:
  // `log` and `reference` may be null; all must outlive the monitor. The frame's clock starts
  // now.
  ConvergenceMonitor(const render::Film& film, const render::FramePlan& plan, StopRules rules,
                     uint32_t frame, ConvergenceLog* log, const image::ImageLayers* reference,
                     double log_interval_s);

  // Called a few times a second from one thread while the frame renders. False: a stop rule
  // fired, hand out no more work.
  bool Poll();
  // After the frame's last sample: the last passes' rows (the frame's last pass is always
  // left to Finish) and the "end" row, measured on `resolved`, the film resolved once for
  // them and for the frame's EXR.
  void Finish(const image::ImageLayers& resolved);

  bool stopped() const { return !stop_reason_.empty(); }
  const std::string& stop_reason() const { return stop_reason_; }  // empty: not stopped
  // The figures at the last pass end, stop or Finish.
  const render::ConvergencePoint& last() const { return last_; }

 private:
  // `resolved`: the film already resolved (else Measure resolves it when samples merged since
  // the last measure).
  // `written`: the image as its file has it (pixels without a sample black), for the frame's
  // end; else as the preview shows it.
  render::ConvergencePoint Measure(const image::ImageLayers* resolved = nullptr, bool written = false) const;
  void CheckPassEnds(const image::ImageLayers* resolved = nullptr);

  const render::Film& film_;
  const render::FramePlan& plan_;
  const StopRules rules_;
  const uint32_t frame_;
  ConvergenceLog* log_;
  const image::ImageLayers* reference_;
  const double log_interval_s_;
  const std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
  double last_log_s_ = 0;
  uint32_t passes_ended_ = 0;
  // Per pass: the samples below its end that the plan's tiles hand out. Every pixel's, except
  // after --resume, whose checkpoint's finished pixels are restored, not rendered.
  std::vector<uint64_t> pass_samples_;
  std::string stop_reason_;
  std::optional<uint64_t> time_stop_samples_;  // merged when --time-limit stopped the frame
  render::ConvergencePoint last_;
  // The figures of the last resolve (error_'s counts are not used), reused while no sample
  // has merged since.
  mutable bool measured_ = false, measured_written_ = false;
  mutable uint64_t measured_samples_ = 0;
  mutable render::ConvergencePoint error_;
  // The film resolved for a measure, kept: resolved into new layers each time, a 960x540 film
  // cost ~40 ms of page faults per measure (memory new to the process), with the film locked.
  mutable image::ImageLayers resolved_;
  mutable std::vector<double> luminance_;  // EstimateError's, kept for the same reason
};

}  // namespace raystack::master
