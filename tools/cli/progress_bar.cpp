#include "tools/cli/progress_bar.h"

#include <fmt/format.h>
#include <unistd.h>

#include <cstdio>

namespace cvd::cli {

ProgressBar::ProgressBar(bool quiet) : quiet_(quiet), tty_(isatty(fileno(stderr))) {}
ProgressBar::~ProgressBar() { finish(); }

void ProgressBar::finish() {
  if (!stage_.empty() && tty_ && !quiet_) std::fputc('\n', stderr);
  stage_.clear();
}

void ProgressBar::update(const RunProgress& p) {
  if (quiet_) return;
  auto now = std::chrono::steady_clock::now();
  if (p.stage != stage_) {
    finish();
    stage_ = p.stage;
    stage_start_ = now;
    last_percent_ = -1;
    // A resumed stage starts part-way: the rate counts only the steps done since.
    first_done_ = p.done > 0 ? p.done - 1 : 0;
  }
  double elapsed = std::chrono::duration<double>(now - stage_start_).count();
  std::string line;
  if (p.total > 0) {
    int percent = static_cast<int>(100.0 * p.done / p.total);
    const long long since = static_cast<long long>(p.done) - first_done_;
    double eta = since > 0 ? elapsed * (p.total - p.done) / static_cast<double>(since) : 0;
    int filled = percent * 24 / 100;
    line = fmt::format("{:>14} [{}{}] {}/{} {:3d}% {:.0f}s eta {:.0f}s {}", p.stage,
                       std::string(filled, '#'), std::string(24 - filled, '.'), p.done, p.total,
                       percent, elapsed, eta, p.message);
    if (!tty_) {
      // Without a terminal print at most every 10%, and the last step.
      if (percent / 10 == last_percent_ / 10 && p.done != p.total) return;
      last_percent_ = percent;
    }
  } else {
    line = fmt::format("{:>14} {} {:.0f}s {}", p.stage, p.done, elapsed, p.message);
    if (!tty_ && std::chrono::duration<double>(now - last_draw_).count() < 5) return;
  }
  last_draw_ = now;
  if (tty_)
    std::fprintf(stderr, "\r%-110.110s", line.c_str());
  else
    std::fprintf(stderr, "%s\n", line.c_str());
  std::fflush(stderr);
}

}  // namespace cvd::cli
