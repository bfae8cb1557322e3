#include "pipeline/geometry/flow_depth_level.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "engine/error.h"

namespace cvd {

void add_inverse_depth_samples(const NamedCamera& ci, const NamedCamera& cj, const cv::Mat& flow,
                               const cv::Mat& mask, InverseDepthSamples& samples, int grid_step) {
  CVD_CHECK(flow.type() == CV_32FC2 && mask.type() == CV_8U && flow.size() == mask.size(),
            "add_inverse_depth_samples: flow and mask must be CV_32FC2 and CV_8U of one size");
  CVD_CHECK(grid_step > 0, "add_inverse_depth_samples: grid_step must be positive");
  const Intrinsics& Ki = ci.intrinsics;
  const Intrinsics& Kj = cj.intrinsics;
  // Frame i's camera coordinates seen from frame j: p = z * (Rji r) + bji.
  const Eigen::Matrix3d Rji = cj.pose.R.transpose() * ci.pose.R;
  const Eigen::Vector3d bji = cj.pose.R.transpose() * (ci.pose.t - cj.pose.t);
  for (int y = grid_step / 2; y < flow.rows; y += grid_step) {
    for (int x = grid_step / 2; x < flow.cols; x += grid_step) {
      if (!mask.at<uint8_t>(y, x)) continue;
      const cv::Vec2f f = flow.at<cv::Vec2f>(y, x);
      const double u = (x + f[0] - Kj.cx) / Kj.fx, v = (y + f[1] - Kj.cy) / Kj.fy;
      const Eigen::Vector3d a = Rji * Eigen::Vector3d((x - Ki.cx) / Ki.fx, (y - Ki.cy) / Ki.fy, 1);
      // (p.x - u p.z) / z = Ax + rho Bx, and the same in y, with rho = 1 / z: least squares.
      const double Ax = a.x() - u * a.z(), Ay = a.y() - v * a.z();
      const double Bx = bji.x() - u * bji.z(), By = bji.y() - v * bji.z();
      const double bb = Bx * Bx + By * By;
      if (!(bb > 1e-18)) continue;  // no baseline across this pixel's ray
      samples.inverse_depth.push_back(-(Ax * Bx + Ay * By) / bb);
      samples.weight.push_back(bb);
    }
  }
}

nlohmann::json FlowDepthLevel::info() const {
  return {{"depth", depth},
          {"source", source},
          {"samples", samples},
          {"median_inverse_depth", median_inverse_depth},
          {"widest_baseline", widest_baseline}};
}

namespace {

double weighted_median(const std::vector<double>& value, const std::vector<double>& weight) {
  std::vector<size_t> order(value.size());
  std::iota(order.begin(), order.end(), size_t(0));
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return value[a] < value[b]; });
  const double total = std::accumulate(weight.begin(), weight.end(), 0.0);
  double cumulative = 0;
  for (size_t k : order) {
    cumulative += weight[k];
    if (cumulative >= 0.5 * total) return value[k];
  }
  return value.empty() ? 0.0 : value[order.back()];
}

}  // namespace

FlowDepthLevel flow_depth_level(const InverseDepthSamples& samples,
                                const std::vector<NamedCamera>& cams, double no_parallax_deg) {
  CVD_CHECK(samples.inverse_depth.size() == samples.weight.size(),
            "flow_depth_level: one weight per sample");
  CVD_CHECK(no_parallax_deg > 0 && no_parallax_deg < 90,
            "flow_depth_level: no_parallax_deg must be in (0, 90)");
  FlowDepthLevel level;
  level.samples = samples.inverse_depth.size();
  for (size_t a = 0; a < cams.size(); ++a)
    for (size_t b = a + 1; b < cams.size(); ++b)
      if (cams[a].registered && cams[b].registered)
        level.widest_baseline =
            std::max(level.widest_baseline, (cams[a].pose.t - cams[b].pose.t).norm());
  if (level.samples > 0) {
    level.median_inverse_depth = weighted_median(samples.inverse_depth, samples.weight);
    if (level.median_inverse_depth > 0 && std::isfinite(1.0 / level.median_inverse_depth)) {
      level.depth = 1.0 / level.median_inverse_depth;
      level.source = "flow";
      return level;
    }
  }
  if (level.widest_baseline > 0) {
    level.depth = level.widest_baseline / std::tan(no_parallax_deg * M_PI / 180.0);
    level.source = "baseline";
  } else {
    level.depth = 1.0;
    level.source = "none";
  }
  return level;
}

}  // namespace cvd
