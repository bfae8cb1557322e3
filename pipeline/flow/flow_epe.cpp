#include "pipeline/flow/flow_epe.h"

#include <cmath>
#include <limits>

#include "engine/error.h"

namespace cvd {

EndpointError endpoint_error(const cv::Mat& flow, const cv::Mat& gt, const cv::Mat& mask) {
  CVD_CHECK(flow.type() == CV_32FC2 && gt.type() == CV_32FC2,
            "endpoint_error: flows must be CV_32FC2");
  CVD_CHECK(flow.size() == gt.size(), "endpoint_error: flow is {}x{} but ground truth is {}x{}",
            flow.cols, flow.rows, gt.cols, gt.rows);
  CVD_CHECK(mask.empty() || (mask.type() == CV_8U && mask.size() == flow.size()),
            "endpoint_error: mask must be CV_8U of the flow's size");
  double sum = 0;
  std::size_t n = 0, above = 0;
  for (int y = 0; y < flow.rows; ++y) {
    const cv::Vec2f* f = flow.ptr<cv::Vec2f>(y);
    const cv::Vec2f* g = gt.ptr<cv::Vec2f>(y);
    const unsigned char* m = mask.empty() ? nullptr : mask.ptr<unsigned char>(y);
    for (int x = 0; x < flow.cols; ++x) {
      if (m && !m[x]) continue;
      if (!(std::abs(g[x][0]) < 1e9f && std::abs(g[x][1]) < 1e9f)) continue;
      const double du = double(f[x][0]) - g[x][0], dv = double(f[x][1]) - g[x][1];
      double e = std::sqrt(du * du + dv * dv);
      if (!std::isfinite(e)) e = std::numeric_limits<double>::infinity();
      sum += e;
      above += e > 3.0;
      ++n;
    }
  }
  CVD_CHECK(n > 0, "endpoint_error: no pixel with known ground truth inside the mask");
  return {sum / double(n), double(above) / double(n), n};
}

}  // namespace cvd
