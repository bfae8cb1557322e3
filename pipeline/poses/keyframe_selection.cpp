#include "pipeline/poses/keyframe_selection.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>
#include <set>

#include "engine/error.h"
#include "pipeline/geometry/median.h"

namespace cvd {

KeyframeOptions parse_keyframe_mode(const std::string& text, const std::string& what) {
  KeyframeOptions o;
  if (text == "auto") return o;
  if (text == "all") {
    o.mode = KeyframeMode::all;
    return o;
  }
  size_t used = 0;
  int count = 0;
  try {
    count = std::stoi(text, &used);
  } catch (...) {
    used = 0;
  }
  if (used != text.size() || text.empty() || count < 2)
    fail(ErrorCategory::invalid_argument,
         "{}: '{}' is not a keyframe setting (use auto, all, or a keyframe count of at least 2)",
         what, text);
  o.mode = KeyframeMode::count;
  o.count = count;
  return o;
}

std::string keyframe_mode_name(const KeyframeOptions& o) {
  switch (o.mode) {
    case KeyframeMode::all:
      return "all";
    case KeyframeMode::automatic:
      return "auto";
    case KeyframeMode::count:
      return std::to_string(o.count);
  }
  return "?";
}

std::vector<double> consecutive_motion(const std::vector<cv::Mat>& frames_bgr, int flow_long_side) {
  CVD_CHECK(flow_long_side >= 16, "keyframes: flow size {} is too small", flow_long_side);
  std::vector<double> motion(frames_bgr.size(), 0.0);
  if (frames_bgr.size() < 2) return motion;
  cv::Ptr<cv::DISOpticalFlow> dis =
      cv::DISOpticalFlow::create(cv::DISOpticalFlow::PRESET_ULTRAFAST);
  auto grey = [&](const cv::Mat& m) {
    double s = double(flow_long_side) / std::max(m.cols, m.rows);
    cv::Mat g, r;
    if (m.channels() == 3)
      cv::cvtColor(m, g, cv::COLOR_BGR2GRAY);
    else
      g = m;
    cv::resize(g, r, cv::Size(), std::min(1.0, s), std::min(1.0, s), cv::INTER_AREA);
    return r;
  };
  cv::Mat prev = grey(frames_bgr[0]);
  const double long_side = std::max(prev.cols, prev.rows);
  std::vector<float> mag;
  for (size_t k = 1; k < frames_bgr.size(); ++k) {
    cv::Mat cur = grey(frames_bgr[k]), flow;
    dis->calc(prev, cur, flow);
    mag.clear();
    for (int y = 0; y < flow.rows; ++y)
      for (int x = 0; x < flow.cols; ++x) {
        cv::Vec2f f = flow.at<cv::Vec2f>(y, x);
        mag.push_back(std::hypot(f[0], f[1]));
      }
    motion[k] = upper_median(mag) / long_side;
    prev = cur;
  }
  return motion;
}

KeyframeSelection select_keyframes(const std::vector<double>& motion, const KeyframeOptions& o) {
  const int n = static_cast<int>(motion.size());
  CVD_CHECK(o.motion_per_keyframe > 0 && o.max_gap >= 1 && o.min_keyframes >= 2,
            "keyframes: bad options");
  KeyframeSelection s;
  std::vector<double> cum(n, 0.0);
  for (int k = 1; k < n; ++k) cum[k] = cum[k - 1] + std::max(0.0, motion[k]);
  s.total_motion = n ? cum[n - 1] : 0.0;
  auto everything = [&](const std::string& why) {
    s.all_frames = true;
    s.keyframes.resize(n);
    for (int k = 0; k < n; ++k) s.keyframes[k] = k;
    s.reason = why;
    return s;
  };
  if (o.mode == KeyframeMode::all) return everything("every frame (--colmap-keyframes all)");
  int wanted =
      o.mode == KeyframeMode::count
          ? o.count
          : std::max(o.min_keyframes,
                     static_cast<int>(std::ceil(s.total_motion / o.motion_per_keyframe)) + 1);
  if (wanted >= n)
    return everything(fmt::format("every frame ({} frames, {} keyframes wanted)", n, wanted));

  // Equal steps of accumulated motion (or of frame index when nothing moved).
  std::set<int> chosen;
  for (int m = 0; m < wanted; ++m) {
    double frac = double(m) / (wanted - 1);
    int k;
    if (s.total_motion > 1e-12) {
      double target = frac * s.total_motion;
      k = static_cast<int>(std::lower_bound(cum.begin(), cum.end(), target) - cum.begin());
      if (k > 0 && target - cum[k - 1] < cum[std::min(k, n - 1)] - target) --k;
      k = std::clamp(k, 0, n - 1);
    } else {
      k = static_cast<int>(std::lround(frac * (n - 1)));
    }
    chosen.insert(k);
  }
  chosen.insert(0);
  chosen.insert(n - 1);
  std::vector<int> keys(chosen.begin(), chosen.end());
  if (o.mode == KeyframeMode::automatic) {
    // No gap longer than max_gap frames: split long ones evenly.
    std::vector<int> filled;
    for (size_t a = 0; a < keys.size(); ++a) {
      filled.push_back(keys[a]);
      if (a + 1 == keys.size()) break;
      int gap = keys[a + 1] - keys[a];
      int parts = (gap + o.max_gap - 1) / o.max_gap;
      for (int p = 1; p < parts; ++p)
        filled.push_back(keys[a] + static_cast<int>(std::lround(double(p) * gap / parts)));
    }
    keys = filled;
    if (keys.size() >= o.use_all_above * n)
      return everything(
          fmt::format("every frame (motion would need {} keyframes of {} frames)", keys.size(), n));
  }
  s.all_frames = false;
  s.keyframes = keys;
  s.reason = fmt::format(
      "{} keyframes of {} frames ({}; accumulated motion {:.2f} of the long side)", keys.size(), n,
      o.mode == KeyframeMode::count
          ? "spaced evenly in motion"
          : fmt::format("one per {:.0f}% of motion, at most {} frames apart",
                        100 * o.motion_per_keyframe, o.max_gap),
      s.total_motion);
  return s;
}

std::vector<std::pair<int, int>> keyframe_match_pairs(int num_frames,
                                                      const std::vector<int>& keyframes,
                                                      int sequential_overlap,
                                                      const KeyframeOptions& o) {
  CVD_CHECK(sequential_overlap >= 1 && o.keyframe_overlap >= 1, "keyframe pairs: bad overlap");
  std::set<std::pair<int, int>> pairs;
  auto add = [&](int a, int b) {
    if (a == b || a < 0 || b < 0 || a >= num_frames || b >= num_frames) return;
    pairs.insert({std::min(a, b), std::max(a, b)});
  };
  const int overlap = std::min(sequential_overlap, std::max(1, o.frame_overlap));
  for (int i = 0; i < num_frames; ++i)
    for (int d = 1; d <= overlap; ++d) add(i, i + d);
  const int K = static_cast<int>(keyframes.size());
  for (int a = 0; a < K; ++a) {
    for (int b = a + 1; b <= std::min(K - 1, a + o.keyframe_overlap); ++b)
      add(keyframes[a], keyframes[b]);
    for (int step = 2 * o.keyframe_overlap; a + step < K; step *= 2)
      add(keyframes[a], keyframes[a + step]);
  }
  // Every frame with its neighbouring keyframes (registration finds 3-D points through them).
  for (int i = 0, a = 0; i < num_frames && K > 0; ++i) {
    while (a + 1 < K && keyframes[a + 1] <= i) ++a;
    if (keyframes[a] <= i) add(i, keyframes[a]);
    if (a + 1 < K) add(i, keyframes[a + 1]);
    if (keyframes[a] > i) add(i, keyframes[a]);
  }
  return {pairs.begin(), pairs.end()};
}

}  // namespace cvd
