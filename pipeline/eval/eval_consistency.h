// Geometric-consistency metrics that need no ground truth (Luo et al., "Consistent Video Depth
// Estimation", SIGGRAPH 2020, section 6.1 "Quantitative evaluation", instability and drift), and
// the flow-reprojection consistency of an output (the paper's spatial loss, as a metric).
//
// 3-D tracks. KLT tracks (cv::goodFeaturesToTrack + cv::calcOpticalFlowPyrLK with a
// forward-backward check) are unprojected with each frame's depth (bilinear sample at the track
// point) and camera-to-world pose: X_k = R_k D_k(x_k) K^-1 [x_k, 1]^T + t_k. For a static scene
// and a perfect reconstruction every track's points coincide.
//
// Instability E_s (the paper: "the average Euclidean distance of the 3-D points of each pair of
// consecutive frames in the track"), for tracks T with n_T >= 2 points:
//   E_s = 1/|T| sum_T  1/(n_T - 1) sum_{k=1}^{n_T - 1} ||X_{k+1} - X_k||
// Drift E_d ("tracks that look stable from frame to frame may still drift over the video"): the
// distance between the first and the last 3-D point of each track, for tracks with n_T >= 2:
//   E_d = 1/|T| sum_T ||X_{n_T} - X_1||
// Caveat: the paper's exact drift formula is not verified here; we recall that it may instead use
// the eigenvalues of each track's 3-D covariance (jitter is isotropic, drift is elongated), so we
// also report that quantity, made robust to near-planar tracks (3 points always give
// lambda_min = 0) by taking a MEDIAN over the tracks with n_T >= 5:
//   drift_eigen_ratio = median_T (lambda_max(C_T) + eps) / (lambda_min(C_T) + eps),
//   C_T = 1/n_T sum_k (X_k - m_T)(X_k - m_T)^T,  m_T the track's centroid, eps = 1e-12.
// A companion to E_s that ignores the ordering of the points:
//   instability_centroid = 1/|T| sum_T 1/n_T sum_k ||X_k - m_T||
//
// Flow-reprojection consistency of frame i towards j, for pixels x (integer pixel centres) valid
// in the flow mask, with positive depth, and in front of camera j:
//   c_i = D_i(x) K^-1 [x, 1]^T,  c_ij = R_j^T (R_i c_i + t_i - t_j),  p_ij = pi(K c_ij)
//   consistency = mean_x ||p_ij - (x + F_ij(x))||_2   (pixels; the paper's L_spatial, eq. 5)
#pragma once
#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <vector>

#include "pipeline/geometry/camera.h"

namespace cvd {

// A 2-D KLT track: points[k] is the observation in frame first_frame + k.
struct Track2D {
  int first_frame = 0;
  std::vector<cv::Point2f> points;
};

struct KltOptions {
  int max_corners = 1000;       // active tracks kept per frame
  double quality_level = 0.01;  // goodFeaturesToTrack
  double min_distance = 8.0;    // px between corners (and to active tracks when re-detecting)
  int window = 21;              // LK window side
  int pyramid_levels = 3;
  double max_forward_backward_px = 1.0;  // drop a point whose backward track misses by more
  int min_track_length = 3;              // shorter tracks are discarded
};

// Tracks corners through consecutive 8-bit grey frames (all the same size), re-detecting corners
// away from active tracks in every frame.
std::vector<Track2D> klt_tracks(const std::vector<cv::Mat>& grey_frames, const KltOptions& opt);

// Unprojects 2-D tracks to world points. depths[k] is CV_32F at the tracks' resolution, K the
// intrinsics at that resolution, poses camera-to-world. Observations without valid depth are
// dropped; tracks left with fewer than 2 points are dropped.
std::vector<std::vector<Eigen::Vector3d>> unproject_tracks(const std::vector<Track2D>& tracks,
                                                           const std::vector<cv::Mat>& depths,
                                                           const std::vector<Pose>& poses,
                                                           const Intrinsics& K);

struct TrackStability {
  double instability = 0;           // E_s
  double drift = 0;                 // E_d: mean first-to-last distance
  double instability_centroid = 0;  // companions, see the header comment
  double drift_eigen_ratio = 0;     // 0 when no track has >= 5 points
  int tracks = 0;                   // tracks with >= 2 points used for E_s
};
TrackStability track_stability(const std::vector<std::vector<Eigen::Vector3d>>& tracks3d);

struct ReprojectionConsistency {
  double mean_px = 0;
  long long pixels = 0;
};

// flow: CV_32FC2 (dx, dy) from frame i to j; mask: CV_8U (non-zero = valid) or empty (all);
// depth_i: CV_32F of the same size; K at that size.
ReprojectionConsistency flow_reprojection_consistency(const cv::Mat& depth_i, const Pose& pose_i,
                                                      const Pose& pose_j, const Intrinsics& K,
                                                      const cv::Mat& flow, const cv::Mat& mask);

// Dense flow i -> j (OpenCV DIS, medium preset) on 8-bit grey frames, with the forward-backward
// check: mask = 255 where ||F_ij(x) + F_ji(x + F_ij(x))|| <= max_fb_px.
void dis_flow_with_mask(const cv::Mat& grey_i, const cv::Mat& grey_j, double max_fb_px,
                        cv::Mat& flow, cv::Mat& mask);

}  // namespace cvd
