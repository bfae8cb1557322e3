// FlowNet2 optical flow (models/flownet2.h) behind the OpticalFlow interface: the images are
// resized to the nearest multiples of 64 (at least 64), run through the network on the CPU in
// f32, and the flow is resized back to the input size with its components rescaled.
#pragma once
#include <filesystem>
#include <memory>
#include <string>

#include "models/flownet2.h"
#include "pipeline/flow/optical_flow.h"

namespace cvd {

class FlowNet2Estimator final : public OpticalFlow {
 public:
  // Loads a .cvdw of FlowNet2 weights under the upstream state_dict names
  // ("flownetc.conv1.0.weight", ...); the header's config "width" (default 1) gives the width.
  explicit FlowNet2Estimator(const std::filesystem::path& weights);
  // Uses an existing network (e.g. random weights for benchmarks).
  explicit FlowNet2Estimator(std::shared_ptr<FlowNet2> net);

  cv::Mat estimate(const cv::Mat& a_bgr, const cv::Mat& b_bgr) override;
  std::string name() const override;
  FlowNet2& network() { return *net_; }

  // The network input size for an image of `size`: each side rounded to the nearest multiple of
  // 64, at least 64.
  static cv::Size network_size(cv::Size size);

 private:
  std::shared_ptr<FlowNet2> net_;
};

}  // namespace cvd
