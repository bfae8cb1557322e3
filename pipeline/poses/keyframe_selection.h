// Keyframes for the pose stage: COLMAP's incremental mapper costs grow much faster than the number
// of frames (its bundle adjustments run over every registered frame again and again), so on long
// clips it reconstructs a set of keyframes only and every other frame is registered to that model
// afterwards (pipeline/poses/colmap_keyframe_registration.h).
//
// Keyframes are spaced by image motion, not by a fixed stride: the median optical-flow magnitude
// between consecutive frames (DIS at a small size), accumulated along the clip, is cut into equal
// steps of `motion_per_keyframe`; no two keyframes are more than `max_gap` frames apart, so a
// still camera still has keyframes and a fast pan gets more of them.
#pragma once
#include <opencv2/core.hpp>
#include <string>
#include <utility>
#include <vector>

namespace cvd {

enum class KeyframeMode {
  all,        // no keyframes: the mapper sees every frame
  automatic,  // spaced by motion (below)
  count,      // exactly `count` keyframes, spaced evenly in accumulated motion
};

struct KeyframeOptions {
  KeyframeMode mode = KeyframeMode::automatic;
  int count = 0;  // for KeyframeMode::count
  // Median flow between consecutive keyframes, as a fraction of the frames' long side.
  double motion_per_keyframe = 0.04;
  int min_keyframes = 12;  // never fewer (all frames when the clip has no more)
  int max_gap = 12;        // frames from one keyframe to the next, at most
  // automatic: when the keyframes would be this fraction of the frames or more, every frame
  // goes to the mapper (keyframes would save little).
  double use_all_above = 0.6;
  int flow_long_side = 160;  // size of the frames the motion is measured on
  // Matching: each keyframe is matched with the next `keyframe_overlap` keyframes, and with
  // keyframes 2^m keyframes away beyond that (loop candidates without a vocabulary tree).
  int keyframe_overlap = 6;
  // Every frame is matched with its next min(`frame_overlap`, the matcher's overlap) frames and
  // with the keyframes before and after it (registration finds its 3-D points through those).
  // 3 instead of the matcher's 10 cut the matching of 7-Scenes frames 0-149 (24 keyframes) from
  // 1,557 pairs / 207 s to 694 / 89 s with the same ATE (README "Poses on a longer clip").
  int frame_overlap = 3;
};

// "auto", "all" or a keyframe count >= 2; throws Error(invalid_argument) naming `what` otherwise.
KeyframeOptions parse_keyframe_mode(const std::string& text, const std::string& what);
std::string keyframe_mode_name(const KeyframeOptions& o);

// Median flow magnitude from frame k-1 to frame k as a fraction of the long side (element 0 is 0),
// measured with DIS (ultrafast) on grey copies at `flow_long_side`.
std::vector<double> consecutive_motion(const std::vector<cv::Mat>& frames_bgr, int flow_long_side);

struct KeyframeSelection {
  bool all_frames = true;      // true: no keyframing (mode all, or it would not pay)
  std::vector<int> keyframes;  // increasing frame indices; first and last frame included
  double total_motion = 0;     // accumulated motion over the clip (fractions of the long side)
  std::string reason;          // one line for the log and run.json
};

// Chooses keyframes from `motion` (as consecutive_motion returns) for a clip of motion.size()
// frames.
KeyframeSelection select_keyframes(const std::vector<double>& motion, const KeyframeOptions& o);

// Image pairs to match when the mapper sees keyframes only (indices, first < second, no
// duplicates, sorted): every frame with the next min(`sequential_overlap`, o.frame_overlap)
// frames, every frame with the keyframes before and after it, every keyframe with the next
// o.keyframe_overlap keyframes and with keyframes 2^m keyframes away (m >= 1 past that window).
// O(N * overlap + K log K) pairs.
std::vector<std::pair<int, int>> keyframe_match_pairs(int num_frames,
                                                      const std::vector<int>& keyframes,
                                                      int sequential_overlap,
                                                      const KeyframeOptions& o);

}  // namespace cvd
