#include "pipeline/flow/flow_consistency.h"

#include <cmath>

#include "engine/error.h"

namespace cvd {

cv::Mat forward_backward_mask(const cv::Mat& flow_ab, const cv::Mat& flow_ba, float threshold_px) {
  CVD_CHECK(flow_ab.type() == CV_32FC2 && flow_ba.type() == CV_32FC2,
            "forward_backward_mask: flows must be CV_32FC2");
  CVD_CHECK(flow_ab.size() == flow_ba.size(),
            "forward_backward_mask: flow sizes differ ({}x{} vs {}x{})", flow_ab.cols, flow_ab.rows,
            flow_ba.cols, flow_ba.rows);
  CVD_CHECK(threshold_px >= 0, "forward_backward_mask: threshold must be >= 0, got {}",
            threshold_px);
  const int w = flow_ab.cols, h = flow_ab.rows;
  const float threshold_sq = threshold_px * threshold_px;
  cv::Mat mask(flow_ab.size(), CV_8U);
  cv::parallel_for_(cv::Range(0, h), [&](const cv::Range& rows) {
    for (int y = rows.start; y < rows.end; ++y) {
      const cv::Vec2f* fab = flow_ab.ptr<cv::Vec2f>(y);
      unsigned char* m = mask.ptr<unsigned char>(y);
      for (int x = 0; x < w; ++x) {
        m[x] = 0;
        const float px = x + fab[x][0], py = y + fab[x][1];
        // The negated comparisons also reject NaN.
        if (!(px >= 0.f && px <= w - 1.f && py >= 0.f && py <= h - 1.f)) continue;
        const int x0 = std::min(static_cast<int>(px), w - 2 < 0 ? 0 : w - 2);
        const int y0 = std::min(static_cast<int>(py), h - 2 < 0 ? 0 : h - 2);
        const int x1 = std::min(x0 + 1, w - 1), y1 = std::min(y0 + 1, h - 1);
        const float ax = px - x0, ay = py - y0;
        const cv::Vec2f& f00 = flow_ba.at<cv::Vec2f>(y0, x0);
        const cv::Vec2f& f01 = flow_ba.at<cv::Vec2f>(y0, x1);
        const cv::Vec2f& f10 = flow_ba.at<cv::Vec2f>(y1, x0);
        const cv::Vec2f& f11 = flow_ba.at<cv::Vec2f>(y1, x1);
        const cv::Vec2f back =
            (1 - ay) * ((1 - ax) * f00 + ax * f01) + ay * ((1 - ax) * f10 + ax * f11);
        const float du = fab[x][0] + back[0], dv = fab[x][1] + back[1];
        const float err_sq = du * du + dv * dv;
        if (err_sq <= threshold_sq) m[x] = 255;  // false for NaN
      }
    }
  });
  return mask;
}

double valid_fraction(const cv::Mat& mask) {
  if (mask.empty()) return 0.0;
  CVD_CHECK(mask.type() == CV_8U, "valid_fraction: mask must be CV_8U, got type {}", mask.type());
  return static_cast<double>(cv::countNonZero(mask)) / static_cast<double>(mask.total());
}

}  // namespace cvd
