#include "pipeline/geometry/flow_triangulation.h"

#include <cmath>

#include "engine/error.h"

namespace cvd {

int triangulate_flow_points(const NamedCamera& ci, const NamedCamera& cj, int i, int j,
                            const cv::Mat& flow, const cv::Mat& mask,
                            std::vector<std::vector<Eigen::Vector3d>>& points,
                            const FlowTriangulationOptions& o) {
  CVD_CHECK(flow.type() == CV_32FC2 && mask.type() == CV_8U && flow.size() == mask.size(),
            "triangulate_flow_points: flow and mask must be CV_32FC2 and CV_8U of one size");
  const Intrinsics& Ki = ci.intrinsics;
  const Intrinsics& Kj = cj.intrinsics;
  const double cos_min = std::cos(o.min_parallax_deg * M_PI / 180.0);
  int kept = 0;
  for (int y = o.grid_step / 2; y < flow.rows; y += o.grid_step) {
    for (int x = o.grid_step / 2; x < flow.cols; x += o.grid_step) {
      if (!mask.at<uint8_t>(y, x)) continue;
      cv::Vec2f f = flow.at<cv::Vec2f>(y, x);
      double xj = x + f[0], yj = y + f[1];
      Eigen::Vector3d ri =
          ci.pose.R * Eigen::Vector3d((x - Ki.cx) / Ki.fx, (y - Ki.cy) / Ki.fy, 1.0);
      Eigen::Vector3d rj =
          cj.pose.R * Eigen::Vector3d((xj - Kj.cx) / Kj.fx, (yj - Kj.cy) / Kj.fy, 1.0);
      Eigen::Vector3d di = ri.normalized(), dj = rj.normalized();
      if (di.dot(dj) > cos_min) continue;  // too little parallax
      // Closest points of the rays oi + a di and oj + b dj.
      Eigen::Vector3d w = ci.pose.t - cj.pose.t;
      double b_ = di.dot(dj), d = di.dot(w), e = dj.dot(w);
      double den = 1.0 - b_ * b_;
      if (den < 1e-12) continue;
      double a = (b_ * e - d) / den, b = (e - b_ * d) / den;
      if (a <= 0 || b <= 0) continue;
      Eigen::Vector3d X = 0.5 * ((ci.pose.t + a * di) + (cj.pose.t + b * dj));
      // Reprojection in both frames.
      auto reproj = [&](const NamedCamera& c, double u, double v) {
        Eigen::Vector3d pc = c.pose.R.transpose() * (X - c.pose.t);
        if (pc.z() <= 0) return 1e9;
        const Intrinsics& K = c.intrinsics;
        return std::hypot(K.fx * pc.x() / pc.z() + K.cx - u, K.fy * pc.y() / pc.z() + K.cy - v);
      };
      if (reproj(ci, x, y) > o.max_reprojection_px || reproj(cj, xj, yj) > o.max_reprojection_px)
        continue;
      points[i].push_back(X);
      points[j].push_back(X);
      ++kept;
    }
  }
  return kept;
}

}  // namespace cvd
