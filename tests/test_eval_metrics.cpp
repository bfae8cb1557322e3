// Evaluation metrics on hand-made inputs with known answers: depth (alignments, thresholds),
// poses (Umeyama, ATE, RPE) and consistency (track stability, flow reprojection).
#include <gtest/gtest.h>

#include <algorithm>
#include <set>

#include <Eigen/Geometry>
#include <opencv2/imgproc.hpp>
#include <random>

#include "engine/error.h"
#include "pipeline/eval/eval_consistency.h"
#include "pipeline/eval/eval_depth_metrics.h"
#include "pipeline/eval/eval_pose_metrics.h"
#include "pipeline/eval/eval_texture_split.h"
#include "tests/eval_plane_scene.h"
#include "tests/test_support.h"

using namespace cvd;
using cvd::test::PlaneScene;

namespace {

cv::Mat random_depth(int w, int h, double lo, double hi, unsigned seed) {
  cv::Mat d(h, w, CV_32F);
  cv::RNG rng(seed);
  rng.fill(d, cv::RNG::UNIFORM, lo, hi);
  return d;
}

DepthEvalResult eval1(const cv::Mat& p, const cv::Mat& g, DepthAlignment a,
                      DepthSpace s = DepthSpace::depth, DepthEvalOptions o = {}) {
  return evaluate_video_depth({p}, {g}, a, s, o);
}

}  // namespace

// ---- depth metrics ------------------------------------------------------------------------------

TEST(EvalDepth, HandComputedValuesAndDeltaThresholds) {
  // Pixels (pred, gt): (2, 1) ratio 2; (3, 2) ratio 1.5; (4, 4) exact; (1.2, 1) ratio 1.2.
  cv::Mat p = (cv::Mat_<float>(1, 4) << 2, 3, 4, 1.2f), g = (cv::Mat_<float>(1, 4) << 1, 2, 4, 1);
  DepthErrors e = eval1(p, g, DepthAlignment::none).mean;
  const double tol = 1e-6;
  EXPECT_NEAR(e.abs_rel, (1.0 + 0.5 + 0 + 0.2) / 4, tol);
  EXPECT_NEAR(e.sq_rel, (1.0 + 0.5 + 0 + 0.04) / 4, tol);
  EXPECT_NEAR(e.rmse, std::sqrt((1.0 + 1.0 + 0 + 0.04) / 4), tol);
  double l2 = std::log(2.0), l15 = std::log(1.5), l12 = std::log(1.2);
  EXPECT_NEAR(e.rmse_log, std::sqrt((l2 * l2 + l15 * l15 + l12 * l12) / 4), tol);
  EXPECT_NEAR(e.delta1, 2.0 / 4, tol);  // 1.0 and 1.2 < 1.25
  EXPECT_NEAR(e.delta2, 3.0 / 4, tol);  // + 1.5 < 1.5625
  EXPECT_NEAR(e.delta3, 3.0 / 4, tol);  // 2 > 1.953
}

TEST(EvalDepth, ConstantBiasIsZeroUnderMedianScaling) {
  cv::Mat g = random_depth(64, 48, 0.5, 10, 1), p = g * 1.1;
  const double tol = 1e-5;  // float storage of 1.1 * g
  EXPECT_NEAR(eval1(p, g, DepthAlignment::none).mean.abs_rel, 0.1, tol);
  EXPECT_NEAR(eval1(p, g, DepthAlignment::none).mean.delta1, 1.0, 0);
  EXPECT_NEAR(eval1(p, g, DepthAlignment::median_frame).mean.abs_rel, 0.0, tol);
  EXPECT_NEAR(eval1(p, g, DepthAlignment::median_video).mean.abs_rel, 0.0, tol);
  EXPECT_NEAR(eval1(p, g, DepthAlignment::lstsq_frame).mean.abs_rel, 0.0, tol);
  // In disparity space the prediction is 1/1.1 of the truth: AbsRel = 1 - 1/1.1.
  EXPECT_NEAR(eval1(p, g, DepthAlignment::none, DepthSpace::disparity).mean.abs_rel, 1 - 1 / 1.1,
              tol);
  EXPECT_NEAR(eval1(p, g, DepthAlignment::median_frame).fits[0].scale, 1 / 1.1, tol);
}

TEST(EvalDepth, LeastSquaresRecoversAffineDepthAndDisparity) {
  cv::Mat g = random_depth(64, 48, 1, 5, 2);
  cv::Mat p = (g - 0.5) / 2.0;  // g = 2 p + 0.5
  DepthEvalResult r = eval1(p, g, DepthAlignment::lstsq_frame);
  EXPECT_NEAR(r.fits[0].scale, 2.0, 1e-4);
  EXPECT_NEAR(r.fits[0].shift, 0.5, 1e-4);
  EXPECT_NEAR(r.mean.abs_rel, 0.0, 1e-5);
  EXPECT_GT(eval1(p, g, DepthAlignment::median_frame).mean.abs_rel, 0.01);  // scale alone fails
  // Affine in disparity: 1/g = 0.3 / p_depth... i.e. p_disp = (g_disp - 0.05) / 3.
  cv::Mat gd = 1.0 / g, pd = (gd - 0.05) / 3.0, p_depth = 1.0 / pd;
  DepthEvalResult rd = eval1(p_depth, g, DepthAlignment::lstsq_frame, DepthSpace::disparity);
  EXPECT_NEAR(rd.fits[0].scale, 3.0, 1e-3);
  EXPECT_NEAR(rd.fits[0].shift, 0.05, 1e-4);
  EXPECT_NEAR(rd.mean.abs_rel, 0.0, 1e-4);
}

TEST(EvalDepth, OneVideoScalePenalisesScaleFlicker) {
  cv::Mat g0 = random_depth(33, 31, 1, 5, 3), g1 = random_depth(33, 31, 1, 5, 4);
  std::vector<cv::Mat> p = {g0 * 1.0, g1 * 2.0}, g = {g0, g1};
  DepthEvalOptions o;
  auto per_frame = evaluate_video_depth(p, g, DepthAlignment::median_frame, DepthSpace::depth, o);
  auto video = evaluate_video_depth(p, g, DepthAlignment::median_video, DepthSpace::depth, o);
  EXPECT_NEAR(per_frame.mean.abs_rel, 0.0, 1e-6);
  // GT/pred ratios: 1 on half the pixels, 0.5 on the other half -> median 0.75 (even count):
  // frame 0 AbsRel 0.25, frame 1 |1.5 - 1| = 0.5, mean 0.375.
  EXPECT_NEAR(video.fits[0].scale, 0.75, 1e-6);
  EXPECT_NEAR(video.per_frame[0].abs_rel, 0.25, 1e-6);
  EXPECT_NEAR(video.per_frame[1].abs_rel, 0.5, 1e-6);
  EXPECT_NEAR(video.mean.abs_rel, 0.375, 1e-6);
  EXPECT_EQ(video.mean.count, 2);
}

TEST(EvalDepth, ValidMaskAndDepthCaps) {
  cv::Mat g = (cv::Mat_<float>(1, 6) << 0, NAN, 2, 30, 4, 0.0005f);
  cv::Mat p = (cv::Mat_<float>(1, 6) << 1, 1, 2, 30, -1, 1);
  DepthEvalOptions o;
  o.max_depth = 10;
  cv::Mat m = valid_depth_mask(p, g, o);
  // 0, NaN, beyond the cap (30 >= 10), negative prediction, below min_depth: invalid.
  EXPECT_EQ(cv::countNonZero(m), 1);
  EXPECT_EQ(m.at<uint8_t>(0, 2), 255);
  o.max_depth = 0;  // no cap: 30 counts again
  EXPECT_EQ(cv::countNonZero(valid_depth_mask(p, g, o)), 2);
  cv::Mat empty_gt(4, 4, CV_32F, cv::Scalar(0));
  auto r = evaluate_video_depth({cv::Mat(4, 4, CV_32F, cv::Scalar(1))}, {empty_gt},
                                DepthAlignment::median_frame, DepthSpace::depth, o);
  EXPECT_EQ(r.skipped_frames, 1);
  EXPECT_EQ(r.mean.count, 0);
}

TEST(EvalDepth, SortedCurveIsMonotoneQuantiles) {
  cv::Mat g = random_depth(50, 40, 1, 3, 5), noise = random_depth(50, 40, 0.8, 1.2, 6);
  cv::Mat p = g.mul(noise);
  auto r = eval1(p, g, DepthAlignment::none);
  ASSERT_EQ(r.sorted_abs_rel.size(), 256u);
  EXPECT_TRUE(std::is_sorted(r.sorted_abs_rel.begin(), r.sorted_abs_rel.end()));
  EXPECT_LE(r.sorted_abs_rel.back(), 0.2 + 1e-6);  // |noise - 1| <= 0.2
  EXPECT_GE(r.sorted_abs_rel.front(), 0.0);
}

// ---- pose metrics -------------------------------------------------------------------------------

static std::vector<Pose> wavy_trajectory(int n) {
  std::vector<Pose> v;
  for (int i = 0; i < n; ++i) {
    Pose p;
    p.R = (Eigen::AngleAxisd(0.05 * i, Eigen::Vector3d::UnitY()) *
           Eigen::AngleAxisd(0.02 * std::sin(i), Eigen::Vector3d::UnitX()))
              .toRotationMatrix();
    p.t = Eigen::Vector3d(0.1 * i, 0.05 * std::sin(0.7 * i), 0.03 * i * i / n);
    v.push_back(p);
  }
  return v;
}

TEST(EvalPose, UmeyamaRecoversKnownSim3AndAteIsZero) {
  std::vector<Pose> gt = wavy_trajectory(30), est;
  Sim3 S;
  S.scale = 2.5;
  S.R = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  S.t = Eigen::Vector3d(1, -2, 0.5);
  // est = S^-1(gt): then the alignment est -> gt is exactly S.
  for (auto& g : gt)
    est.push_back({S.R.transpose() * g.R, S.R.transpose() * (g.t - S.t) / S.scale});
  PoseErrors e = absolute_trajectory_error(est, gt, true);
  EXPECT_NEAR(e.alignment.scale, 2.5, 1e-9);
  EXPECT_LT((e.alignment.R - S.R).norm(), 1e-9);
  EXPECT_LT((e.alignment.t - S.t).norm(), 1e-9);
  EXPECT_LT(e.ate_rmse, 1e-9);
  RelativePoseErrors r = relative_pose_error(est, gt, 1, e.alignment);
  EXPECT_LT(r.trans_rmse, 1e-9);
  EXPECT_LT(r.rot_mean_deg, 1e-5);
  // Without scale the fit cannot undo the 2.5x: ATE clearly non-zero.
  EXPECT_GT(absolute_trajectory_error(est, gt, false).ate_rmse, 0.1);
}

TEST(EvalPose, AteOfKnownOffsets) {
  // Positions perturbed by +-d along z alternately (zero mean, orthogonal to the motion):
  // the best alignment is close to the identity and ATE RMSE close to d.
  std::vector<Pose> gt = wavy_trajectory(40), est = gt;
  const double d = 0.01;
  for (size_t i = 0; i < est.size(); ++i) est[i].t.z() += (i % 2 ? d : -d);
  PoseErrors e = absolute_trajectory_error(est, gt, false);
  EXPECT_NEAR(e.ate_rmse, d, 0.1 * d);  // tolerance 10%: the fit absorbs a little
}

TEST(EvalPose, RpeOfKnownPerturbation) {
  std::vector<Pose> gt = wavy_trajectory(10), est = gt;
  const Eigen::Vector3d d(0.03, -0.04, 0);  // |d| = 0.05, a jump between frames 4 and 5
  for (int i = 5; i < 10; ++i) est[i].t += d;
  RelativePoseErrors r = relative_pose_error(est, gt, 1);  // identity alignment
  ASSERT_EQ(r.pairs, 9);
  EXPECT_NEAR(r.trans_mean, 0.05 / 9, 1e-12);
  EXPECT_NEAR(r.trans_rmse, std::sqrt(0.05 * 0.05 / 9), 1e-12);
  EXPECT_NEAR(r.rot_mean_deg, 0.0, 1e-6);
  // At delta 3 the jump lies inside pairs (2,5), (3,6), (4,7): 3 of 7 pairs.
  RelativePoseErrors r3 = relative_pose_error(est, gt, 3);
  ASSERT_EQ(r3.pairs, 7);
  EXPECT_NEAR(r3.trans_mean, 3 * 0.05 / 7, 1e-12);
  // A 2 degree rotation of frame 5 alone affects pairs (4,5) and (5,6) by 2 degrees each.
  est = gt;
  est[5].R =
      est[5].R * Eigen::AngleAxisd(2.0 * M_PI / 180, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  RelativePoseErrors rr = relative_pose_error(est, gt, 1);
  EXPECT_NEAR(rr.rot_mean_deg, 2.0 * 2 / 9, 1e-6);
  EXPECT_NEAR(rotation_angle_deg(Eigen::Matrix3d::Identity()), 0.0, 1e-12);
}

// The motion's direction in the first camera's frame: no similarity changes it, and a path
// whose every step turns 90 degrees in the cameras' frames scores 90 however well its positions
// align.
TEST(EvalPose, RpeDirectionIgnoresSimilarityAndSeesSidewaysMotion) {
  std::vector<Pose> gt = wavy_trajectory(20), est;
  Sim3 S;
  S.scale = 0.3;
  S.R = Eigen::AngleAxisd(1.1, Eigen::Vector3d(0, 1, 2).normalized()).toRotationMatrix();
  S.t = Eigen::Vector3d(4, 0, -1);
  for (auto& g : gt) est.push_back(S.apply(g));
  RelativePoseErrors same = relative_pose_error(est, gt, 3);
  ASSERT_EQ(same.dir_pairs, 17);
  EXPECT_NEAR(same.dir_mean_deg, 0.0, 1e-5);
  // The same positions, every camera turned 90 degrees about its own motion-orthogonal axis:
  // each step's motion, seen from the turned camera, is 90 degrees off.
  std::vector<Pose> turned = gt;
  for (size_t i = 0; i + 1 < gt.size(); ++i) {
    const Eigen::Vector3d m = gt[i].R.transpose() * (gt[i + 1].t - gt[i].t);  // camera frame
    const Eigen::Vector3d axis = m.unitOrthogonal();
    turned[i].R = gt[i].R * Eigen::AngleAxisd(M_PI / 2, axis).toRotationMatrix();
  }
  RelativePoseErrors side = relative_pose_error(turned, gt, 1);
  ASSERT_EQ(side.dir_pairs, 19);
  EXPECT_NEAR(side.dir_mean_deg, 90.0, 1e-6);
  // Positions are untouched: ATE sees nothing.
  EXPECT_LT(absolute_trajectory_error(turned, gt, true).ate_rmse, 1e-9);
  // A camera that does not move: no direction, the pair is left out.
  std::vector<Pose> still = gt;
  still[1].t = still[0].t;
  EXPECT_EQ(relative_pose_error(still, gt, 1).dir_pairs, 18);
}

// ---- consistency metrics ------------------------------------------------------------------------

TEST(EvalConsistency, JitteredTracksGiveKnownInstability) {
  // X_k = c + n_k, n_k ~ N(0, s^2 I): ||X_{k+1} - X_k|| has mean sqrt(2) s E||z|| with
  // E||z|| = 2 sqrt(2 / pi) for z ~ N(0, I_3), i.e. E_s = 4 s / sqrt(pi).
  std::mt19937 rng(7);
  std::normal_distribution<double> n01(0, 1);
  const double s = 0.01;
  const int T = 2000, L = 20;
  std::vector<std::vector<Eigen::Vector3d>> tracks(T);
  for (auto& t : tracks) {
    Eigen::Vector3d c(n01(rng), n01(rng), 5 + n01(rng));
    for (int k = 0; k < L; ++k) t.push_back(c + s * Eigen::Vector3d(n01(rng), n01(rng), n01(rng)));
  }
  TrackStability st = track_stability(tracks);
  EXPECT_EQ(st.tracks, T);
  const double ez = 2 * std::sqrt(2 / M_PI);
  EXPECT_NEAR(st.instability, 4 * s / std::sqrt(M_PI), 0.02 * 4 * s / std::sqrt(M_PI));  // 2%
  EXPECT_NEAR(st.drift, std::sqrt(2.0) * s * ez, 0.05 * std::sqrt(2.0) * s * ez);        // 5%
  // Spread about the centroid: deviation variance s^2 (1 - 1/L); E||.|| ~ ez s sqrt(1 - 1/L)
  // (the norm of a slightly correlated sample: 3% tolerance).
  EXPECT_NEAR(st.instability_centroid, ez * s * std::sqrt(1 - 1.0 / L), 0.03 * ez * s);
  // Isotropic jitter: covariance eigenvalue ratio of 20 samples stays small (< 10).
  EXPECT_LT(st.drift_eigen_ratio, 10.0);
  EXPECT_GT(st.drift_eigen_ratio, 1.0);
}

TEST(EvalConsistency, LinearDriftIsElongated) {
  std::vector<std::vector<Eigen::Vector3d>> tracks(1);
  for (int k = 0; k < 10; ++k) tracks[0].push_back(Eigen::Vector3d(0.01 * k, 0, 3));
  TrackStability st = track_stability(tracks);
  EXPECT_NEAR(st.instability, 0.01, 1e-12);
  EXPECT_NEAR(st.drift, 0.09, 1e-12);
  EXPECT_GT(st.drift_eigen_ratio, 1e6);  // lambda_min = 0 (regularised): a line is elongated
}

TEST(EvalConsistency, UnprojectionAndFlowReprojection) {
  Intrinsics K{100, 100, 80, 60, 160, 120};
  Pose pi;
  pi.t = Eigen::Vector3d(1, 2, 3);
  cv::Mat depth(120, 160, CV_32F, cv::Scalar(2.0f));
  Track2D t{0, {cv::Point2f(80, 60), cv::Point2f(130, 60)}};
  auto pts = unproject_tracks({t}, {depth, depth}, {pi, pi}, K);
  ASSERT_EQ(pts.size(), 1u);
  EXPECT_LT((pts[0][0] - Eigen::Vector3d(1, 2, 5)).norm(), 1e-9);
  EXPECT_LT((pts[0][1] - Eigen::Vector3d(2, 2, 5)).norm(), 1e-6);  // (130-80)/100*2 = 1
  // Camera j moved 0.1 along its x axis: a plane at depth 2 shifts by -fx 0.1 / 2 = -5 px.
  Pose pj = pi;
  pj.t += pi.R * Eigen::Vector3d(0.1, 0, 0);
  cv::Mat flow(120, 160, CV_32FC2, cv::Scalar(-5.0f, 0.0f));
  auto r = flow_reprojection_consistency(depth, pi, pj, K, flow, cv::Mat());
  EXPECT_EQ(r.pixels, 160 * 120);
  EXPECT_NEAR(r.mean_px, 0.0, 1e-5);
  cv::Mat off(120, 160, CV_32FC2, cv::Scalar(-2.0f, 4.0f));  // error (3, 4): 5 px
  cv::Mat mask(120, 160, CV_8U, cv::Scalar(0));
  mask(cv::Rect(0, 0, 10, 10)).setTo(255);
  r = flow_reprojection_consistency(depth, pi, pj, K, off, mask);
  EXPECT_EQ(r.pixels, 100);
  EXPECT_NEAR(r.mean_px, 5.0, 1e-5);
}

TEST(EvalConsistency, KltTracksFollowKnownMotionAndStabilityDetectsFlicker) {
  PlaneScene sc(8);
  KltOptions o;
  auto tracks = klt_tracks(sc.grey, o);
  ASSERT_GT(tracks.size(), 50u);
  double err = 0;
  int n = 0;
  for (auto& t : tracks)
    for (size_t k = 1; k < t.points.size(); ++k, ++n)
      err += std::abs((t.points[k].x - t.points[k - 1].x) + 1.0f) +
             std::abs(t.points[k].y - t.points[k - 1].y);
  EXPECT_LT(err / n, 0.1);  // px: the camera moves +x, the image content 1 px/frame to -x
  TrackStability good = track_stability(unproject_tracks(tracks, sc.depth, sc.poses, sc.K));
  std::vector<cv::Mat> flicker;
  for (size_t k = 0; k < sc.depth.size(); ++k) flicker.push_back(sc.depth[k] * (k % 2 ? 1.1 : 0.9));
  TrackStability bad = track_stability(unproject_tracks(tracks, flicker, sc.poses, sc.K));
  // Consistent depth: E_s of the order of the KLT error (0.1 px * Z / fx = 2 mm); flickering
  // depth (+-10% of 2 m) moves points by ~0.4 m between frames.
  EXPECT_LT(good.instability, 0.01);
  EXPECT_GT(bad.instability, 0.2);
}

// ---- depth by texture ---------------------------------------------------------------------------

// A flat frame is low texture everywhere, strong noise almost nowhere (under 5% of its pixels,
// where neighbours happen to be alike), at any resolution.
TEST(EvalTextureSplit, FlatFramesAreLowTextureAtAnyResolution) {
  for (cv::Size size : {cv::Size(640, 480), cv::Size(160, 120)}) {
    cv::Mat flat(size, CV_8U, cv::Scalar(128)), noise(size, CV_8U);
    cv::RNG(3).fill(noise, cv::RNG::UNIFORM, 0, 256);
    const cv::Size depth_size(size.width / 2, size.height / 2);
    const cv::Mat low_flat = low_texture_mask(flat, depth_size, {});
    const cv::Mat low_noise = low_texture_mask(noise, depth_size, {});
    EXPECT_EQ(low_flat.size(), depth_size);
    EXPECT_EQ(cv::countNonZero(low_flat), depth_size.area());
    EXPECT_LT(cv::countNonZero(low_noise), depth_size.area() / 20);
  }
  EXPECT_THROW(low_texture_mask(cv::Mat(4, 4, CV_32F), {4, 4}, {}), Error);
}

// The left 30% of each frame is flat and its depth 20% too far; the textured rest is exact. The
// median scale comes from the textured majority (1), so the split gives AbsRel 0.2 on the flat
// pixels and 0 on the others, with their shares.
TEST(EvalTextureSplit, ErrorsOfEachRegionWithTheFramesScale) {
  std::vector<cv::Mat> preds, gts, greys;
  for (int k = 0; k < 3; ++k) {
    cv::Mat g = random_depth(200, 100, 1.0, 3.0, 20 + k);
    cv::Mat p = g * (0.5 + k);  // any per-frame scale: median_frame removes it
    cv::Mat grey(100, 200, CV_8U);
    cv::RNG(k).fill(grey, cv::RNG::UNIFORM, 0, 256);
    const cv::Rect flat(0, 0, 60, 100);
    grey(flat).setTo(90);
    p(flat) *= 1.2;
    preds.push_back(p);
    gts.push_back(g);
    greys.push_back(grey);
  }
  const DepthEvalResult r = evaluate_video_depth(preds, gts, DepthAlignment::median_frame,
                                                 DepthSpace::depth, DepthEvalOptions{});
  const TextureSplit s = depth_errors_by_texture(preds, gts, greys, r, DepthEvalOptions{});
  // The flat region's border columns see the noise through the 3x3 Sobel at 256 px: a few
  // columns of the 60 are textured.
  EXPECT_NEAR(s.low_texture.share, 0.3, 0.03);
  EXPECT_NEAR(s.textured.share + s.low_texture.share, 1.0, 1e-12);
  EXPECT_EQ(s.low_texture.pixels + s.textured.pixels, 3 * 200 * 100);
  // A few noise pixels whose neighbourhood happens to be smooth count as low texture (exact depth).
  EXPECT_NEAR(s.low_texture.abs_rel, 0.2, 0.005);
  EXPECT_EQ(s.low_texture.delta1, 1.0);
  EXPECT_LT(s.textured.abs_rel, 0.2 * 0.05);  // the few border columns of the flat region
  EXPECT_THROW(depth_errors_by_texture(preds, gts, greys, DepthEvalResult{}, DepthEvalOptions{}),
               Error);
}
