#include "pipeline/poses/track_bundle_adjustment.h"

#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <glog/logging.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <thread>

#include "engine/error.h"

namespace cvd {

namespace {

// cam[0..2]: world-to-camera rotation (angle-axis), cam[3..5]: camera centre in the world.
struct Reprojection {
  double u, v, cx, cy;
  template <typename T>
  bool operator()(const T* cam, const T* X, const T* focal, T* r) const {
    const T d[3] = {X[0] - cam[3], X[1] - cam[4], X[2] - cam[5]};
    T p[3];
    ceres::AngleAxisRotatePoint(cam, d, p);
    if (p[2] <= T(1e-12)) return false;  // behind the camera: the step is rejected
    r[0] = focal[0] * p[0] / p[2] + T(cx) - T(u);
    r[1] = focal[0] * p[1] / p[2] + T(cy) - T(v);
    return true;
  }
};

// Holds the distance of one camera centre from the fixed one (the scale gauge).
struct CentreDistance {
  Eigen::Vector3d fixed;
  double distance, weight;
  template <typename T>
  bool operator()(const T* cam, T* r) const {
    const T dx = cam[3] - T(fixed.x()), dy = cam[4] - T(fixed.y()), dz = cam[5] - T(fixed.z());
    r[0] = T(weight) * (ceres::sqrt(dx * dx + dy * dy + dz * dz + T(1e-30)) - T(distance)) /
           T(distance);
    return true;
  }
};

double focal_for_fov(double fov_deg, int width) {
  return 0.5 * width / std::tan(0.5 * fov_deg * M_PI / 180.0);
}

}  // namespace

double reprojection_error_px(const TrackCameras& cams, const Eigen::Vector3d& X,
                             const PixelTrack::Observation& ob) {
  const size_t k = static_cast<size_t>(ob.frame);
  const Eigen::Vector3d p = cams.R[k].transpose() * (X - cams.c[k]);
  if (p.z() <= 1e-12) return std::numeric_limits<double>::infinity();
  return std::hypot(cams.focal * p.x() / p.z() + cams.cx - ob.x,
                    cams.focal * p.y() / p.z() + cams.cy - ob.y);
}

namespace {

// One Ceres solve over every observation of the usable frames.
TrackBundleReport adjust_once(const std::vector<PixelTrack>& tracks,
                              const std::vector<bool>& usable, std::vector<Eigen::Vector3d>& points,
                              TrackCameras& cams, const TrackBundleOptions& o) {
  const size_t n = cams.R.size();
  TrackBundleReport rep;
  // Parameters: per usable frame [angle-axis of R^T, centre].
  std::vector<std::array<double, 6>> cam(n);
  int fixed = -1;
  for (size_t k = 0; k < n; ++k) {
    const Eigen::Matrix3d Rwc = cams.R[k].transpose();
    ceres::RotationMatrixToAngleAxis(Rwc.data(), cam[k].data());
    for (int i = 0; i < 3; ++i) cam[k][3 + i] = cams.c[k][i];
    if (fixed < 0 && usable[k]) fixed = static_cast<int>(k);
  }
  if (fixed < 0) return rep;
  double focal = cams.focal;

  ceres::Problem problem;
  ceres::LossFunction* loss = new ceres::HuberLoss(o.huber_px);  // owned by the problem
  auto* ordering = new ceres::ParameterBlockOrdering;
  std::vector<bool> camera_used(n, false);
  // Observations whose point starts behind the camera are left out (a residual cannot start
  // there).
  auto in_front = [&](size_t k, const Eigen::Vector3d& X) {
    return (cams.R[k].transpose() * (X - cams.c[k])).z() > 1e-12;
  };
  for (size_t t = 0; t < tracks.size(); ++t) {
    int views = 0;
    for (const auto& ob : tracks[t].observations)
      if (usable[size_t(ob.frame)] && in_front(size_t(ob.frame), points[t])) ++views;
    if (views < 2) continue;
    for (const auto& ob : tracks[t].observations) {
      const size_t k = static_cast<size_t>(ob.frame);
      if (!usable[k] || !in_front(k, points[t])) continue;
      auto* cost = new ceres::AutoDiffCostFunction<Reprojection, 2, 6, 3, 1>(
          new Reprojection{ob.x, ob.y, cams.cx, cams.cy});
      problem.AddResidualBlock(cost, loss, cam[k].data(), points[t].data(), &focal);
      camera_used[k] = true;
      ++rep.residuals;
    }
    ordering->AddElementToGroup(points[t].data(), 0);
  }
  if (rep.residuals == 0 || !camera_used[size_t(fixed)]) {
    delete ordering;
    return rep;
  }
  for (size_t k = 0; k < n; ++k)
    if (camera_used[k]) ordering->AddElementToGroup(cam[k].data(), 1);
  ordering->AddElementToGroup(&focal, 1);
  problem.SetParameterBlockConstant(cam[size_t(fixed)].data());
  if (o.refine_focal) {
    problem.SetParameterLowerBound(&focal, 0, focal_for_fov(o.max_fov_deg, cams.width));
    problem.SetParameterUpperBound(&focal, 0, focal_for_fov(o.min_fov_deg, cams.width));
  } else {
    problem.SetParameterBlockConstant(&focal);
  }
  // Scale gauge: the camera farthest from the fixed one keeps its distance.
  int far = -1;
  double far_d = 0;
  for (size_t k = 0; k < n; ++k) {
    if (!camera_used[k]) continue;
    const double d = (cams.c[k] - cams.c[size_t(fixed)]).norm();
    if (d > far_d) far_d = d, far = static_cast<int>(k);
  }
  if (far >= 0 && far_d > 0) {
    auto* cost = new ceres::AutoDiffCostFunction<CentreDistance, 1, 6>(new CentreDistance{
        cams.c[size_t(fixed)], far_d, std::sqrt(static_cast<double>(rep.residuals))});
    problem.AddResidualBlock(cost, nullptr, cam[size_t(far)].data());
  }

  ceres::Solver::Options so;
  int used_cameras = 0;
  for (bool u : camera_used) used_cameras += u;
  so.linear_solver_type = used_cameras <= 400 ? ceres::DENSE_SCHUR : ceres::ITERATIVE_SCHUR;
  if (so.linear_solver_type == ceres::ITERATIVE_SCHUR) so.preconditioner_type = ceres::SCHUR_JACOBI;
  so.linear_solver_ordering.reset(ordering);
  so.max_num_iterations = o.max_iterations;
  so.num_threads = o.threads > 0
                       ? o.threads
                       : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  so.minimizer_progress_to_stdout = false;
  so.logging_type = ceres::SILENT;
  so.function_tolerance = 1e-7;
  ceres::Solver::Summary summary;
  // Ceres reports through glog; cvd reports the outcome itself (spdlog), so glog stays quiet.
  FLAGS_minloglevel = google::GLOG_FATAL;
  FLAGS_logtostderr = false;
  ceres::Solve(so, &problem, &summary);
  rep.initial_cost = summary.initial_cost;
  rep.final_cost = summary.final_cost;
  rep.iterations = static_cast<int>(summary.iterations.size());
  rep.usable = summary.IsSolutionUsable();
  if (!rep.usable) return rep;

  for (size_t k = 0; k < n; ++k) {
    if (!camera_used[k]) continue;
    Eigen::Matrix3d Rwc;
    ceres::AngleAxisToRotationMatrix(cam[k].data(), Rwc.data());
    cams.R[k] = Rwc.transpose();
    cams.c[k] = Eigen::Vector3d(cam[k][3], cam[k][4], cam[k][5]);
  }
  cams.focal = focal;
  double sum = 0;
  int count = 0;
  for (size_t t = 0; t < tracks.size(); ++t)
    for (const auto& ob : tracks[t].observations) {
      if (!usable[size_t(ob.frame)]) continue;
      const double e = reprojection_error_px(cams, points[t], ob);
      if (!std::isfinite(e)) continue;
      sum += e * e;
      ++count;
    }
  rep.rms_px = count ? std::sqrt(sum / count) : 0;
  return rep;
}

}  // namespace

TrackBundleReport bundle_adjust_tracks(const std::vector<PixelTrack>& tracks,
                                       const std::vector<bool>& usable,
                                       std::vector<Eigen::Vector3d>& points, TrackCameras& cams,
                                       const TrackBundleOptions& o) {
  const size_t n = cams.R.size();
  CVD_CHECK(cams.c.size() == n && usable.size() == n && points.size() == tracks.size(),
            "bundle_adjust_tracks: {} rotations, {} centres, {} usable flags, {} points for {} "
            "tracks",
            n, cams.c.size(), usable.size(), points.size(), tracks.size());
  CVD_CHECK(cams.focal > 0 && cams.width > 0, "bundle_adjust_tracks: no focal / image size");
  TrackBundleReport first = adjust_once(tracks, usable, points, cams, o);
  if (!first.usable || !(o.outlier_px > 0)) return first;
  // Second pass without the observations the first left beyond outlier_px (the Huber loss still
  // gives gross outliers a linear pull).
  std::vector<PixelTrack> kept;
  std::vector<size_t> source;
  std::vector<Eigen::Vector3d> kept_points;
  int dropped = 0;
  for (size_t t = 0; t < tracks.size(); ++t) {
    PixelTrack k;
    for (const auto& ob : tracks[t].observations) {
      if (!usable[size_t(ob.frame)]) continue;
      if (reprojection_error_px(cams, points[t], ob) <= o.outlier_px)
        k.observations.push_back(ob);
      else
        ++dropped;
    }
    if (k.observations.size() < 2) continue;
    kept.push_back(std::move(k));
    source.push_back(t);
    kept_points.push_back(points[t]);
  }
  TrackCameras second_cams = cams;
  TrackBundleReport second = adjust_once(kept, usable, kept_points, second_cams, o);
  if (!second.usable) {
    first.outliers = dropped;
    return first;
  }
  cams = second_cams;
  for (size_t i = 0; i < kept.size(); ++i) points[source[i]] = kept_points[i];
  second.initial_cost = first.initial_cost;
  second.iterations += first.iterations;
  second.outliers = dropped;
  return second;
}

}  // namespace cvd
