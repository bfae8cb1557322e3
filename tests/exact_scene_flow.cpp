#include "exact_scene_flow.h"

#include <cmath>
#include <cstdint>

namespace cvd::test {

void exact_scene_flow(const SyntheticScene& s, size_t a, size_t b, cv::Mat& flow, cv::Mat& mask) {
  const SyntheticFrame &fa = s.frames[a], &fb = s.frames[b];
  const Intrinsics& K = s.intrinsics;
  flow.create(fa.depth.size(), CV_32FC2);
  mask = cv::Mat::zeros(fa.depth.size(), CV_8U);
  for (int y = 0; y < flow.rows; ++y)
    for (int x = 0; x < flow.cols; ++x) {
      const double z = fa.depth.at<float>(y, x);
      const Eigen::Vector3d X =
          fa.pose.transform(Eigen::Vector3d((x - K.cx) / K.fx * z, (y - K.cy) / K.fy * z, z));
      const Eigen::Vector3d p = fb.pose.R.transpose() * (X - fb.pose.t);
      const double u = K.fx * p.x() / p.z() + K.cx, v = K.fy * p.y() / p.z() + K.cy;
      flow.at<cv::Vec2f>(y, x) = cv::Vec2f(float(u - x), float(v - y));
      const bool inside = p.z() > 0 && u >= 0 && v >= 0 && u <= flow.cols - 1 && v <= flow.rows - 1;
      if (!inside || fa.moving_mask.at<uint8_t>(y, x)) continue;
      const float zb = fb.depth.at<float>(int(std::lround(v)), int(std::lround(u)));
      if (std::abs(p.z() / zb - 1.0) < 0.01) mask.at<uint8_t>(y, x) = 255;
    }
}

}  // namespace cvd::test
