#include "pipeline/geometry/epipolar_distance.h"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>

#include "engine/error.h"
#include "pipeline/geometry/median.h"

namespace cvd {

namespace {

Eigen::Matrix3d cross_matrix(const Eigen::Vector3d& t) {
  Eigen::Matrix3d m;
  m << 0, -t.z(), t.y(), t.z(), 0, -t.x(), -t.y(), t.x(), 0;
  return m;
}

}  // namespace

double median_epipolar_distance(const cv::Mat& flow, const cv::Mat& mask, const NamedCamera& a,
                                const NamedCamera& b, int stride) {
  CVD_CHECK(flow.type() == CV_32FC2, "median_epipolar_distance: the flow must be CV_32FC2");
  CVD_CHECK(mask.empty() || (mask.type() == CV_8U && mask.size() == flow.size()),
            "median_epipolar_distance: the mask must be CV_8U of the flow's size");
  CVD_CHECK(stride >= 1, "median_epipolar_distance: stride must be >= 1, got {}", stride);
  // Camera a's coordinates in camera b's: x_b = R x_a + t.
  const Eigen::Matrix3d R = b.pose.R.transpose() * a.pose.R;
  const Eigen::Vector3d t = b.pose.R.transpose() * (a.pose.t - b.pose.t);
  const Eigen::Matrix3d Ka = a.intrinsics.K(), Kb = b.intrinsics.K();
  const Eigen::Matrix3d Ka_inv = Ka.inverse(), Kb_inv = Kb.inverse();
  const double scale = std::max(a.pose.t.norm() + b.pose.t.norm(), 1e-300);
  const bool no_baseline = t.norm() <= 1e-12 * scale;
  // With a baseline: F = Kb^-T [t]x R Ka^-1 (t normalised: the distance does not depend on its
  // length). Without one: the homography Kb R Ka^-1 that every static point follows.
  const Eigen::Matrix3d F =
      no_baseline ? Eigen::Matrix3d::Zero()
                  : Eigen::Matrix3d(Kb_inv.transpose() * cross_matrix(t.normalized()) * R * Ka_inv);
  const Eigen::Matrix3d H = Kb * R * Ka_inv;
  std::vector<double> d;
  d.reserve(static_cast<size_t>((flow.rows / stride + 1) * (flow.cols / stride + 1)));
  for (int y = 0; y < flow.rows; y += stride) {
    const cv::Vec2f* f = flow.ptr<cv::Vec2f>(y);
    const uint8_t* m = mask.empty() ? nullptr : mask.ptr<uint8_t>(y);
    for (int x = 0; x < flow.cols; x += stride) {
      if (m && !m[x]) continue;
      const Eigen::Vector3d p(x, y, 1.0);
      const Eigen::Vector3d q(x + f[x][0], y + f[x][1], 1.0);
      if (!std::isfinite(q.x()) || !std::isfinite(q.y())) continue;
      if (no_baseline) {
        const Eigen::Vector3d h = H * p;
        if (h.z() <= 0) continue;
        d.push_back((h.head<2>() / h.z() - q.head<2>()).norm());
        continue;
      }
      const Eigen::Vector3d Fp = F * p, Ftq = F.transpose() * q;
      const double den = Fp.x() * Fp.x() + Fp.y() * Fp.y() + Ftq.x() * Ftq.x() + Ftq.y() * Ftq.y();
      if (!(den > 0)) continue;
      d.push_back(std::abs(q.dot(Fp)) / std::sqrt(den));
    }
  }
  return d.empty() ? -1.0 : median(std::move(d));
}

EpipolarCheck check_epipolar_distances(const std::vector<double>& distances_px, int long_side_px,
                                       const EpipolarCheckOptions& o) {
  EpipolarCheck c;
  c.drop.assign(distances_px.size(), false);
  std::vector<double> known;
  for (double v : distances_px)
    if (v >= 0) known.push_back(v);
  if (known.empty()) return c;
  c.median_px = median(known);
  c.threshold_px = std::max(o.factor * c.median_px, o.floor_fraction * long_side_px);
  std::vector<size_t> above;
  for (size_t k = 0; k < distances_px.size(); ++k)
    if (distances_px[k] > c.threshold_px) above.push_back(k);
  // The worst first; beyond the cap the rest stay.
  std::stable_sort(above.begin(), above.end(),
                   [&](size_t i, size_t j) { return distances_px[i] > distances_px[j]; });
  const auto cap = static_cast<size_t>(o.max_dropped_fraction * static_cast<double>(known.size()));
  for (size_t r = 0; r < above.size(); ++r) {
    if (r < cap)
      c.drop[above[r]] = true;
    else
      ++c.capped;
  }
  return c;
}

}  // namespace cvd
