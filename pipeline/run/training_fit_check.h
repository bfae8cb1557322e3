// After test-time training: does the depth explain the flow with these cameras?
//
// The geometric loss after training is, to within its small disparity term, the mean distance in
// depth-resolution pixels between where the flow says a pixel went and where its depth and the
// cameras put it. With cameras that fit the frames it ends near the flow's own noise; where it
// stays far above it, no depth reconciles the flow with the cameras (cameras that are wrong, as
// estimated cameras are on clips with little parallax, or much of the scene moving), and the
// depth is unreliable whatever its look.
//
// Measured (README "Does the depth explain the flow"), 7-Scenes kitchen at 256 px, where the
// flow's forward-backward tolerance (1 px at 640 px) is 0.4 px: 15 runs ending at AbsRel
// 0.080-0.106 finished at 0.24-0.91 px (the demo at 0.11); cameras from the flow on frames 0-39
// (AbsRel 0.58, worse than a flat plane's 0.28) at 2.83 px. The warning's threshold is 5x the
// tolerance (2 px at 256 px): it names runs as far off as that one. It cannot name cameras that
// are wrong in a way a wrong depth explains as well (COLMAP's bad draw on frames 0-39: 0.23 px).
#pragma once
#include <nlohmann/json.hpp>

#include <opencv2/core.hpp>

namespace cvd {

struct TrainingFitOptions {
  double tolerance_factor = 5.0;  // warn above this many forward-backward tolerances
};

// `final_loss`: the geometric loss after training (pixels at `depth_size`); `fb_threshold_px`:
// the flow's forward-backward threshold at the flow's resolution `flow_size`. Warns when the
// loss exceeds the threshold; returns the record for run.json (training.fit).
nlohmann::json check_training_fit(double final_loss, double fb_threshold_px, cv::Size flow_size,
                                  cv::Size depth_size, const TrainingFitOptions& options = {});

}  // namespace cvd
