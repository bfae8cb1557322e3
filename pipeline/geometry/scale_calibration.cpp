#include "pipeline/geometry/scale_calibration.h"

#include <spdlog/spdlog.h>
#include <algorithm>
#include <cmath>
#include <limits>

#include "engine/error.h"
#include "pipeline/geometry/median.h"

namespace cvd {
namespace {

double depth_at(const cv::Mat& d, int x, int y) {
  return d.depth() == CV_32F ? double(d.at<float>(y, x)) : d.at<double>(y, x);
}

// Network depth at sub-pixel (u, v) (pixel centres at integer coordinates): bilinear when the four
// neighbours are valid, otherwise the nearest pixel; NaN when that is invalid or outside.
double sample_depth(const cv::Mat& d, double u, double v, double min_depth) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  if (!(u > -0.5 && v > -0.5 && u < d.cols - 0.5 && v < d.rows - 0.5)) return nan;
  int x0 = int(std::floor(u)), y0 = int(std::floor(v));
  if (x0 >= 0 && y0 >= 0 && x0 + 1 < d.cols && y0 + 1 < d.rows) {
    double a = depth_at(d, x0, y0), b = depth_at(d, x0 + 1, y0);
    double c = depth_at(d, x0, y0 + 1), e = depth_at(d, x0 + 1, y0 + 1);
    if (a > min_depth && b > min_depth && c > min_depth && e > min_depth) {
      double fx = u - x0, fy = v - y0;
      return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + e * fx) * fy;
    }
  }
  int xn = std::clamp(int(std::lround(u)), 0, d.cols - 1);
  int yn = std::clamp(int(std::lround(v)), 0, d.rows - 1);
  double n = depth_at(d, xn, yn);
  return n > min_depth ? n : nan;
}

}  // namespace

int ScaleCalibrationResult::num_valid() const {
  return int(std::count(frame_valid.begin(), frame_valid.end(), true));
}

ScaleCalibrationResult calibrate_scale(
    const std::vector<NamedCamera>& cameras, const std::vector<cv::Mat>& depths,
    const std::vector<std::vector<Eigen::Vector3d>>& observed_points,
    const ScaleCalibrationOptions& options) {
  const size_t n = cameras.size();
  CVD_CHECK(depths.size() == n && observed_points.size() == n,
            "calibrate_scale: {} cameras but {} depth maps and {} point lists", n, depths.size(),
            observed_points.size());
  CVD_CHECK(options.min_points >= 1, "calibrate_scale: min_points must be >= 1, got {}",
            options.min_points);
  ScaleCalibrationResult result;
  result.frame_scales.assign(n, std::numeric_limits<double>::quiet_NaN());
  result.frame_sample_counts.assign(n, 0);
  result.frame_valid.assign(n, false);

  double sum = 0;
  int valid = 0;
  for (size_t i = 0; i < n; ++i) {
    const NamedCamera& cam = cameras[i];
    const cv::Mat& d = depths[i];
    if (!cam.registered || d.empty()) continue;
    CVD_CHECK(d.channels() == 1 && (d.depth() == CV_32F || d.depth() == CV_64F),
              "calibrate_scale: depth map of frame '{}' must be one-channel float, got type {}",
              cam.name, d.type());
    CVD_CHECK(cam.intrinsics.valid(), "calibrate_scale: frame '{}' has no valid intrinsics",
              cam.name);
    Intrinsics k = cam.intrinsics;
    if (k.width != d.cols || k.height != d.rows) k = k.scaled_to(d.cols, d.rows);
    const Pose world_to_camera = cam.pose.inverse();
    std::vector<double> ratios;
    ratios.reserve(observed_points[i].size());
    for (const Eigen::Vector3d& xw : observed_points[i]) {
      Eigen::Vector3d xc = world_to_camera.transform(xw);
      if (!(xc.z() > options.min_depth)) continue;
      double u = k.fx * xc.x() / xc.z() + k.cx, v = k.fy * xc.y() / xc.z() + k.cy;
      double dn = sample_depth(d, u, v, options.min_depth);
      if (!std::isfinite(dn)) continue;
      ratios.push_back(dn / xc.z());
    }
    result.frame_sample_counts[i] = int(ratios.size());
    if (int(ratios.size()) < options.min_points) continue;
    double s = median(std::move(ratios));
    if (!std::isfinite(s) || s <= 0) continue;
    result.frame_scales[i] = s;
    result.frame_valid[i] = true;
    sum += s;
    ++valid;
  }
  if (valid == 0)
    fail(ErrorCategory::numerical,
         "scale calibration: none of the {} frames has {} or more sparse points with valid depth "
         "(registered frame, point in front of the camera, inside the image, network depth > 0)",
         n, options.min_points);
  result.scale = sum / valid;
  if (valid < int(n))
    spdlog::warn(
        "scale calibration: {} of {} frames have too few valid points (< {}); they are "
        "excluded from the loss",
        int(n) - valid, n, options.min_points);
  result.cameras = cameras;
  for (auto& c : result.cameras) c.pose.t *= result.scale;
  return result;
}

ScaleCalibrationResult calibrate_scale(const std::vector<NamedCamera>& cameras,
                                       const std::vector<cv::Mat>& depths, const ColmapModel& model,
                                       const ScaleCalibrationOptions& options) {
  std::vector<std::vector<Eigen::Vector3d>> points;
  points.reserve(cameras.size());
  for (const auto& c : cameras) points.push_back(model.observed_points(c.name));
  return calibrate_scale(cameras, depths, points, options);
}

}  // namespace cvd
