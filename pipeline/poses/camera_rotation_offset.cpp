#include "pipeline/poses/camera_rotation_offset.h"

#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <glog/logging.h>

#include <algorithm>
#include <cmath>
#include <thread>

#include "engine/error.h"
#include "pipeline/poses/flow_camera_init.h"

namespace cvd {

namespace {

// One observation through a given camera turned by the offset: p = offset^T R_k^T (X - c_k), the
// parameter w being the angle-axis of offset^T.
struct OffsetReprojection {
  double u, v, cx, cy, focal;
  Eigen::Matrix3d world_to_camera;  // R_k^T
  Eigen::Vector3d centre;
  template <typename T>
  bool operator()(const T* w, const T* X, T* r) const {
    T q[3];
    for (int i = 0; i < 3; ++i)
      q[i] = T(world_to_camera(i, 0)) * (X[0] - T(centre.x())) +
             T(world_to_camera(i, 1)) * (X[1] - T(centre.y())) +
             T(world_to_camera(i, 2)) * (X[2] - T(centre.z()));
    T p[3];
    ceres::AngleAxisRotatePoint(w, q, p);
    if (p[2] <= T(1e-12)) return false;  // behind the camera: the step is rejected
    r[0] = T(focal) * p[0] / p[2] + T(cx) - T(u);
    r[1] = T(focal) * p[1] / p[2] + T(cy) - T(v);
    return true;
  }
};

Eigen::Matrix3d offset_matrix(const double w[3]) {
  Eigen::Matrix3d offset_t;  // offset^T
  ceres::AngleAxisToRotationMatrix(w, offset_t.data());
  return offset_t.transpose();
}

TrackCameras turned(const TrackCameras& given, const std::vector<bool>& usable,
                    const Eigen::Matrix3d& offset) {
  TrackCameras cams = given;
  for (size_t k = 0; k < cams.R.size(); ++k)
    if (usable[k]) cams.R[k] = given.R[k] * offset;
  return cams;
}

// One Ceres solve of the offset w and the points over every observation of `keep` (all when
// empty) whose point starts in front of its camera.
TrackBundleReport solve(const std::vector<PixelTrack>& tracks, const std::vector<bool>& usable,
                        const std::vector<std::vector<bool>>& keep,
                        std::vector<Eigen::Vector3d>& points, const TrackCameras& given,
                        double w[3], const TrackBundleOptions& o) {
  TrackBundleReport rep;
  const TrackCameras start = turned(given, usable, offset_matrix(w));
  ceres::Problem problem;
  ceres::LossFunction* loss = new ceres::HuberLoss(o.huber_px);  // owned by the problem
  auto* ordering = new ceres::ParameterBlockOrdering;
  auto kept = [&](size_t t, size_t i) { return keep.empty() || keep[t][i]; };
  auto in_front = [&](size_t k, const Eigen::Vector3d& X) {
    return (start.R[k].transpose() * (X - start.c[k])).z() > 1e-12;
  };
  for (size_t t = 0; t < tracks.size(); ++t) {
    const auto& obs = tracks[t].observations;
    std::vector<size_t> use;
    for (size_t i = 0; i < obs.size(); ++i) {
      const size_t k = static_cast<size_t>(obs[i].frame);
      if (usable[k] && kept(t, i) && in_front(k, points[t])) use.push_back(i);
    }
    if (use.size() < 2) continue;
    for (size_t i : use) {
      const size_t k = static_cast<size_t>(obs[i].frame);
      auto* cost = new ceres::AutoDiffCostFunction<OffsetReprojection, 2, 3, 3>(
          new OffsetReprojection{obs[i].x, obs[i].y, given.cx, given.cy, given.focal,
                                 given.R[k].transpose(), given.c[k]});
      problem.AddResidualBlock(cost, loss, w, points[t].data());
      ++rep.residuals;
    }
    ordering->AddElementToGroup(points[t].data(), 0);
  }
  if (rep.residuals == 0) {
    delete ordering;
    return rep;
  }
  ordering->AddElementToGroup(w, 1);
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_SCHUR;
  so.linear_solver_ordering.reset(ordering);
  so.max_num_iterations = o.max_iterations;
  so.num_threads = o.threads > 0
                       ? o.threads
                       : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  so.logging_type = ceres::SILENT;
  so.function_tolerance = 1e-7;
  ceres::Solver::Summary summary;
  FLAGS_minloglevel = google::GLOG_FATAL;  // cvd reports the outcome itself
  FLAGS_logtostderr = false;
  ceres::Solve(so, &problem, &summary);
  rep.initial_cost = summary.initial_cost;
  rep.final_cost = summary.final_cost;
  rep.iterations = static_cast<int>(summary.iterations.size());
  rep.usable = summary.IsSolutionUsable();
  return rep;
}

}  // namespace

RotationOffsetReport adjust_rotation_offset(const std::vector<PixelTrack>& tracks,
                                            const std::vector<bool>& usable,
                                            std::vector<Eigen::Vector3d>& points,
                                            TrackCameras& cams, const TrackBundleOptions& o) {
  const size_t n = cams.R.size();
  CVD_CHECK(cams.c.size() == n && usable.size() == n,
            "adjust_rotation_offset: {} rotations, {} centres, {} usable flags", n, cams.c.size(),
            usable.size());
  CVD_CHECK(cams.focal > 0 && cams.width > 0, "adjust_rotation_offset: no focal / image size");
  points = intersect_track_rays(tracks, usable, cams);
  place_points_in_front(tracks, usable, cams, points);
  double w[3] = {0, 0, 0};
  RotationOffsetReport out;
  const TrackCameras given = cams;
  TrackBundleReport first = solve(tracks, usable, {}, points, given, w, o);
  out.adjustment = first;
  if (!first.usable || first.residuals == 0) {
    w[0] = w[1] = w[2] = 0;  // nothing learnt: the given cameras stay as they are
  } else if (o.outlier_px > 0) {
    // Second pass without the observations the first left beyond outlier_px.
    const TrackCameras after_first = turned(given, usable, offset_matrix(w));
    std::vector<std::vector<bool>> keep(tracks.size());
    int dropped = 0;
    for (size_t t = 0; t < tracks.size(); ++t) {
      const auto& obs = tracks[t].observations;
      keep[t].resize(obs.size());
      for (size_t i = 0; i < obs.size(); ++i) {
        keep[t][i] = reprojection_error_px(after_first, points[t], obs[i]) <= o.outlier_px;
        if (usable[size_t(obs[i].frame)] && !keep[t][i]) ++dropped;
      }
    }
    std::vector<Eigen::Vector3d> second_points = points;
    double w2[3] = {w[0], w[1], w[2]};
    TrackBundleReport second = solve(tracks, usable, keep, second_points, given, w2, o);
    if (second.usable && second.residuals > 0) {
      std::copy(w2, w2 + 3, w);
      points = std::move(second_points);
      second.initial_cost = first.initial_cost;
      second.iterations += first.iterations;
      out.adjustment = second;
    }
    out.adjustment.outliers = dropped;
  }
  out.offset = offset_matrix(w);
  out.angle_deg = std::sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]) * 180.0 / M_PI;
  cams = turned(given, usable, out.offset);
  double sum = 0;
  int count = 0;
  for (size_t t = 0; t < tracks.size(); ++t)
    for (const auto& ob : tracks[t].observations) {
      if (!usable[size_t(ob.frame)]) continue;
      const double e = reprojection_error_px(cams, points[t], ob);
      if (!std::isfinite(e) || e > o.outlier_px) continue;
      sum += e * e;
      ++count;
    }
  out.adjustment.rms_px = count ? std::sqrt(sum / count) : 0;
  return out;
}

}  // namespace cvd
