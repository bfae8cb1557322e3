// A console progress display for the pipeline's stages: one line per stage, redrawn in place on
// a terminal (carriage return), with counts, a bar and an ETA; plain lines when not a terminal.
#pragma once
#include <chrono>
#include <string>

#include "pipeline/run/run_options.h"

namespace cvd::cli {

class ProgressBar {
 public:
  explicit ProgressBar(bool quiet);
  ~ProgressBar();
  void update(const RunProgress& p);
  void finish();  // ends the current line

 private:
  bool quiet_, tty_;
  std::string stage_;
  std::chrono::steady_clock::time_point stage_start_, last_draw_;
  long long first_done_ = 0;
  int last_percent_ = -1;
};

}  // namespace cvd::cli
