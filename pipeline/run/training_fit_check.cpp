#include "pipeline/run/training_fit_check.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>

namespace cvd {

nlohmann::json check_training_fit(double final_loss, double fb_threshold_px, cv::Size flow_size,
                                  cv::Size depth_size, const TrainingFitOptions& options) {
  const double flow_long = std::max(flow_size.width, flow_size.height);
  const double depth_long = std::max(depth_size.width, depth_size.height);
  const double tolerance = flow_long > 0 ? fb_threshold_px * depth_long / flow_long : 0.0;
  const double threshold = options.tolerance_factor * tolerance;
  const bool poor = std::isfinite(final_loss) && threshold > 0 && final_loss > threshold;
  if (poor)
    spdlog::warn(
        "training: the depth does not explain the flow with these cameras (geometric loss {:.2f} "
        "px after training, {:.1f}x the flow's forward-backward tolerance of {:.2f} px at the "
        "depth resolution): the cameras are likely wrong (e.g. estimated on a clip with little "
        "parallax) or much of the scene moves, and the depth is unreliable; given poses "
        "(--poses) or a clip with more camera motion help (run.json: training.fit)",
        final_loss, final_loss / tolerance, tolerance);
  return {{"geometric_loss_px", final_loss},
          {"flow_tolerance_px", tolerance},
          {"warn_above_px", threshold},
          {"depth_explains_flow", !poor}};
}

}  // namespace cvd
