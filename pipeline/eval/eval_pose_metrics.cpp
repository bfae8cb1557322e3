// ATE / RPE after Umeyama alignment; formulas in eval_pose_metrics.h.
#include "pipeline/eval/eval_pose_metrics.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "engine/error.h"

namespace cvd {

double rotation_angle_deg(const Eigen::Matrix3d& R) {
  double c = std::clamp((R.trace() - 1.0) * 0.5, -1.0, 1.0);
  return std::acos(c) * 180.0 / 3.14159265358979323846;
}

Sim3 umeyama_alignment(const std::vector<Eigen::Vector3d>& src,
                       const std::vector<Eigen::Vector3d>& dst, bool with_scale) {
  CVD_CHECK(src.size() == dst.size(), "umeyama_alignment: {} source and {} target points",
            src.size(), dst.size());
  CVD_CHECK(src.size() >= 2, "umeyama_alignment: needs at least 2 corresponding positions, got {}",
            src.size());
  Eigen::Matrix3Xd a(3, src.size()), b(3, dst.size());
  for (size_t i = 0; i < src.size(); ++i) {
    a.col(i) = src[i];
    b.col(i) = dst[i];
  }
  Eigen::Matrix4d T = Eigen::umeyama(a, b, with_scale);
  Sim3 s;
  Eigen::Matrix3d sR = T.topLeftCorner<3, 3>();
  s.scale = with_scale ? std::cbrt(sR.determinant()) : 1.0;
  s.R = sR / s.scale;
  s.t = T.topRightCorner<3, 1>();
  return s;
}

PoseErrors absolute_trajectory_error(const std::vector<Pose>& est, const std::vector<Pose>& gt,
                                     bool with_scale) {
  CVD_CHECK(est.size() == gt.size(), "absolute_trajectory_error: {} estimated and {} GT poses",
            est.size(), gt.size());
  PoseErrors r;
  r.frames = int(est.size());
  if (est.size() < 2) return r;
  std::vector<Eigen::Vector3d> a, b;
  for (size_t i = 0; i < est.size(); ++i) {
    a.push_back(est[i].t);
    b.push_back(gt[i].t);
  }
  r.alignment = umeyama_alignment(a, b, with_scale);
  double sq = 0, sum = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    double e = (b[i] - r.alignment.apply(a[i])).norm();
    r.ate_per_frame.push_back(e);
    sq += e * e;
    sum += e;
  }
  r.ate_rmse = std::sqrt(sq / a.size());
  r.ate_mean = sum / a.size();
  std::vector<double> s = r.ate_per_frame;
  std::sort(s.begin(), s.end());
  r.ate_max = s.back();
  r.ate_median = s.size() % 2 ? s[s.size() / 2] : 0.5 * (s[s.size() / 2 - 1] + s[s.size() / 2]);
  return r;
}

RelativePoseErrors relative_pose_error(const std::vector<Pose>& est, const std::vector<Pose>& gt,
                                       int delta, const Sim3& alignment) {
  CVD_CHECK(est.size() == gt.size(), "relative_pose_error: {} estimated and {} GT poses",
            est.size(), gt.size());
  CVD_CHECK(delta >= 1, "relative_pose_error: delta must be >= 1, got {}", delta);
  RelativePoseErrors r;
  r.delta = delta;
  double tsq = 0, tsum = 0, rsum = 0, rsq = 0, dsum = 0;
  for (size_t i = 0; i + delta < est.size(); ++i) {
    Pose p0 = alignment.apply(est[i]), p1 = alignment.apply(est[i + delta]);
    Pose rel_est = p0.inverse() * p1;
    Pose rel_gt = gt[i].inverse() * gt[i + delta];
    Pose e = rel_gt.inverse() * rel_est;
    double te = e.t.norm(), re = rotation_angle_deg(e.R);
    tsq += te * te;
    tsum += te;
    rsum += re;
    rsq += re * re;
    ++r.pairs;
    const double ne = rel_est.t.norm(), ng = rel_gt.t.norm();
    if (ne > 0 && ng > 0) {
      const double c = std::clamp(rel_est.t.dot(rel_gt.t) / (ne * ng), -1.0, 1.0);
      dsum += std::acos(c) * 180.0 / M_PI;
      ++r.dir_pairs;
    }
  }
  if (r.dir_pairs > 0) r.dir_mean_deg = dsum / r.dir_pairs;
  if (r.pairs == 0) return r;
  r.trans_rmse = std::sqrt(tsq / r.pairs);
  r.trans_mean = tsum / r.pairs;
  r.rot_mean_deg = rsum / r.pairs;
  r.rot_rmse_deg = std::sqrt(rsq / r.pairs);
  return r;
}

}  // namespace cvd
