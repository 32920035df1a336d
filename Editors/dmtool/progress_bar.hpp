// dmtool's progress bar: "label [#####.....]  50%" redrawn in place on
// stderr, only when stderr is a terminal, so pipes and logs stay clean.
#pragma once

#include <functional>
#include <string>

namespace dmtool {

/// A text progress bar on stderr. Inactive (draws nothing) when stderr is
/// not a terminal. Redraws only when the shown percentage changes; the
/// destructor ends the line. Single-threaded: feed it from one thread.
class ProgressBar {
 public:
  explicit ProgressBar(std::string label);
  ~ProgressBar();
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;

  /// Shows `fraction` (clamped to [0, 1]; NaN is ignored).
  void update(double fraction);
  /// Ends the bar's line (once); later updates start a new bar.
  void finish();
  /// A callback for the SDK's progress options that forwards to update().
  /// The bar must outlive the callback's use.
  std::function<void(double)> callback();
  /// True when the bar draws (stderr is a terminal).
  bool enabled() const noexcept { return enabled_; }

 private:
  std::string label_;
  bool enabled_ = false;
  bool drawing_ = false;
  int shown_ = -1;  // percentage currently drawn
};

}  // namespace dmtool
