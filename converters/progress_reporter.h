// The library's side of a Progress callback (include/mlfe/pipeline.h): fractions of one call
// mapped into the share of a step, kept non-decreasing, and Cancelled thrown when the callback
// asks to stop; and the guard that removes a call's finished outputs when a later step fails or
// is cancelled. Private to mlfe::pipeline.
#pragma once
#include <mlfe/formats/atomic_file.h>
#include <mlfe/pipeline.h>

#include <algorithm>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace mlfe::pipeline::detail {

class Reporter {
 public:
  Reporter() = default;
  explicit Reporter(Progress progress)
      : progress_(std::make_shared<Progress>(std::move(progress))), last_(std::make_shared<double>(0)) {}

  /// Reports `fraction` (0..1) of this reporter's share, in `stage`; throws Cancelled when the
  /// callback returns false.
  void operator()(double fraction, const std::string& stage) const {
    if (!progress_ || !*progress_) return;
    const double f = lo_ + (hi_ - lo_) * std::clamp(fraction, 0.0, 1.0);
    *last_ = std::max(*last_, f);
    if (!(*progress_)(*last_, stage)) throw Cancelled();
  }
  /// The last report of a call: its outputs exist, so the callback's answer is not asked for.
  void finish(const std::string& stage) const {
    if (progress_ && *progress_) (*progress_)(std::max(*last_, hi_), stage);
  }
  /// The share [lo, hi] of this reporter's share (0 ≤ lo ≤ hi ≤ 1).
  Reporter share(double lo, double hi) const {
    Reporter r = *this;
    r.lo_ = lo_ + (hi_ - lo_) * lo;
    r.hi_ = lo_ + (hi_ - lo_) * hi;
    return r;
  }
  /// As a Progress (for BuildOptions::fraction_progress); empty when this one is.
  Progress as_progress() const {
    if (!progress_ || !*progress_) return {};
    const Reporter r = *this;
    return [r](double f, const std::string& stage) {
      r(f, stage);
      return true;
    };
  }
  explicit operator bool() const { return progress_ && *progress_; }

 private:
  std::shared_ptr<Progress> progress_;
  std::shared_ptr<double> last_;
  double lo_ = 0, hi_ = 1;
};

/// The outputs a call has finished so far, removed again if the call fails or is cancelled
/// before release(): each write is atomic, and this makes the call's outputs all or nothing.
/// Within an OutputBatch (the command line) the batch already holds them back; nothing is
/// removed then (the path may hold an older file the batch keeps).
class OutputGuard {
 public:
  OutputGuard() : active_(!OutputBatch::active()) {}
  OutputGuard(const OutputGuard&) = delete;
  OutputGuard& operator=(const OutputGuard&) = delete;
  ~OutputGuard() {
    if (!active_) return;
    std::error_code ec;
    for (const auto& p : paths_) std::filesystem::remove(p, ec);
  }
  void add(const std::string& path) { paths_.push_back(path); }
  void release() { active_ = false; }

 private:
  bool active_;
  std::vector<std::string> paths_;
};

}  // namespace mlfe::pipeline::detail
