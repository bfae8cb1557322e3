// Dense Inverse Search optical flow (Kroeger et al. 2016) through cv::DISOpticalFlow, on grayscale.
#pragma once
#include <opencv2/video/tracking.hpp>

#include <optional>
#include <string>

#include "pipeline/flow/optical_flow.h"

namespace cvd {

enum class DisPreset { ultrafast, fast, medium };

// "ultrafast" | "fast" | "medium"; throws Error(invalid_argument) for anything else.
DisPreset parse_dis_preset(const std::string& name);
const char* dis_preset_name(DisPreset preset);

struct DisFlowOptions {
  // Default chosen from the Sintel measurements (bench/sintel_epe.sh): medium has the lowest EPE
  // on all 4 scene/pass pairs (0.31-0.34 px alley_1, 1.58-1.95 px cave_2, vs 0.45-0.66 and
  // 2.07-2.71 for fast/ultrafast) for ~230 ms per direction at 1024x436 on 2 busy cores
  // (bench_flow: fast 48 ms, ultrafast 29 ms).
  DisPreset preset = DisPreset::medium;
  // Unset fields keep the preset's values (OpenCV 4.6: ultrafast has no variational refinement,
  // fast and medium 5 iterations; alpha 20, delta 5, gamma 10).
  std::optional<int> variational_refinement_iterations;
  std::optional<float> variational_refinement_alpha;  // smoothness weight
  std::optional<float> variational_refinement_delta;  // colour-constancy weight
  std::optional<float> variational_refinement_gamma;  // gradient-constancy weight
  std::optional<int> finest_scale;                    // 0 = full resolution
};

class DisFlowEstimator final : public OpticalFlow {
 public:
  explicit DisFlowEstimator(const DisFlowOptions& options = {});
  cv::Mat estimate(const cv::Mat& a_bgr, const cv::Mat& b_bgr) override;
  std::string name() const override;
  const DisFlowOptions& options() const { return options_; }

 private:
  DisFlowOptions options_;
  cv::Ptr<cv::DISOpticalFlow> dis_;
};

}  // namespace cvd
