// The interface every optical-flow method implements (OpenCV DIS now, FlowNet2 later).
#pragma once
#include <opencv2/core.hpp>

#include <string>

namespace cvd {

class OpticalFlow {
 public:
  virtual ~OpticalFlow() = default;

  // Dense flow from image a to image b, in pixels, as CV_32FC2 (u, v) of a's size: pixel (x, y)
  // of a is seen at (x + u, y + v) in b. Both images are 8-bit BGR (CV_8UC3) of the same size.
  // Not required to be thread-safe: use one estimator per thread.
  virtual cv::Mat estimate(const cv::Mat& a_bgr, const cv::Mat& b_bgr) = 0;

  // Short human-readable name with the settings that matter, e.g. "dis-medium".
  virtual std::string name() const = 0;
};

}  // namespace cvd
