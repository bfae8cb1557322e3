// Camera trajectory metrics against ground-truth poses (Sturm et al., "A Benchmark for the
// Evaluation of RGB-D SLAM Systems", IROS 2012; the TUM RGB-D benchmark's ATE and RPE).
//
// Poses are camera-to-world (pipeline/geometry/camera.h): position c_i = t_i, rotation R_i.
// Alignment: the similarity S = (s, R, t) minimising sum_i ||g_i - (s R c_i + t)||^2 over the
// estimated positions c_i and GT positions g_i (Umeyama 1991, via Eigen::umeyama; `with_scale`
// false fits SE(3)). The aligned estimate is P'_i = (R R_i, s R c_i + t).
//   ATE  = sqrt(1/N sum_i ||g_i - (s R c_i + t)||^2)                        (RMSE of positions)
// Relative pose error at frame step delta (pairs i, i + delta), with the aligned estimate:
//   E_i  = (Q_i^-1 Q_{i+delta})^-1 (P'_i^-1 P'_{i+delta})        (Q = GT, P' = aligned estimate)
//   RPE_trans = sqrt(1/M sum_i ||trans(E_i)||^2)                        (RMSE, GT units)
//   RPE_rot   = 1/M sum_i angle(rot(E_i)),  angle(R) = acos((tr R - 1)/2)  (mean, degrees)
//   RPE_dir   = 1/M' sum_i angle(trans(P'_i^-1 P'_{i+delta}), trans(Q_i^-1 Q_{i+delta}))
//               (mean, degrees): the direction of the motion in the first camera's frame, which
//               no alignment (scale, rotation) changes; over the M' pairs where both move.
// delta = 1 gives the consecutive-frame (drift per frame) error.
// Why the direction: on a short, nearly straight path the Sim(3) fit of ATE can lay any nearly
// straight trajectory onto the ground truth by rotating it, whatever way each camera faces; a
// small ATE then hides cameras that move sideways to where they look (7-Scenes kitchen frames
// 0-39: COLMAP's ATE 0.45 cm, its motion 100 degrees off in the cameras' frames).
#pragma once
#include <Eigen/Core>
#include <vector>

#include "pipeline/geometry/camera.h"

namespace cvd {

struct Sim3 {
  double scale = 1.0;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  Eigen::Vector3d apply(const Eigen::Vector3d& x) const { return scale * R * x + t; }
  // The pose P mapped by this similarity: (R P.R, s R P.t + t).
  Pose apply(const Pose& p) const { return {R * p.R, scale * R * p.t + t}; }
};

// Similarity taking `src` positions onto `dst` (least squares). Needs >= 3 non-collinear points
// for a unique rotation; with fewer the result is whatever Eigen::umeyama returns.
Sim3 umeyama_alignment(const std::vector<Eigen::Vector3d>& src,
                       const std::vector<Eigen::Vector3d>& dst, bool with_scale = true);

struct PoseErrors {
  Sim3 alignment;       // estimate -> GT
  double ate_rmse = 0;  // GT units
  double ate_mean = 0, ate_median = 0, ate_max = 0;
  std::vector<double> ate_per_frame;  // position error of each frame after alignment
  int frames = 0;
};

// ATE after Sim(3) (or SE(3)) alignment; est[i] and gt[i] are the same frame.
PoseErrors absolute_trajectory_error(const std::vector<Pose>& est, const std::vector<Pose>& gt,
                                     bool with_scale = true);

struct RelativePoseErrors {
  int delta = 1;
  double trans_rmse = 0, trans_mean = 0;  // GT units
  double rot_mean_deg = 0, rot_rmse_deg = 0;
  int pairs = 0;
  double dir_mean_deg = 0;  // RPE_dir; 0 when no pair moves
  int dir_pairs = 0;
};

// RPE at frame step `delta`; `est` is transformed by `alignment` first (pass the ATE's
// alignment; the identity for already aligned poses).
RelativePoseErrors relative_pose_error(const std::vector<Pose>& est, const std::vector<Pose>& gt,
                                       int delta, const Sim3& alignment = {});

// Rotation angle of R in degrees, robust to rounding (acos argument clamped).
double rotation_angle_deg(const Eigen::Matrix3d& R);

}  // namespace cvd
