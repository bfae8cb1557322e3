// Evaluation: depth / pose / consistency metrics on hand-made inputs with known answers, the GT
// and run readers (including their rejection of malformed files), and the HTML report rendered
// by headless Chromium.
#include <gtest/gtest.h>

#include <algorithm>
#include <set>

#include <Eigen/Geometry>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

#include "engine/error.h"
#include "pipeline/eval/eval_consistency.h"
#include "pipeline/eval/eval_depth_metrics.h"
#include "pipeline/eval/eval_pose_metrics.h"
#include "pipeline/eval/eval_readers.h"
#include "pipeline/eval/eval_report.h"
#include "pipeline/eval/eval_run.h"
#include "pipeline/io/image_io.h"
#include "pipeline/io/pfm_io.h"
#include "pipeline/io/sparse_depth_io.h"
#include "pipeline/io/trajectory_io.h"
#include "tests/test_support.h"

namespace fs = std::filesystem;
using namespace cvd;

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

void write_text(const fs::path& p, const std::string& s) {
  fs::create_directories(p.parent_path());
  std::ofstream(p) << s;
}

// Expects `f` to throw cvd::Error whose message contains every string of `needles`.
template <class F>
void expect_error_naming(F&& f, std::initializer_list<std::string> needles) {
  try {
    f();
    ADD_FAILURE() << "expected a cvd::Error";
  } catch (const Error& e) {
    for (auto& n : needles)
      EXPECT_NE(std::string(e.what()).find(n), std::string::npos)
          << "message '" << e.what() << "' lacks '" << n << "'";
  }
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

// A textured fronto-parallel plane at depth Z seen by a camera sliding along x by `step` per
// frame: frame k is the texture shifted by fx * step * k / Z pixels (exact for a plane).
struct PlaneScene {
  Intrinsics K{100, 100, 80, 60, 160, 120};
  double Z = 2.0, step = 0.02;  // 1 px per frame
  std::vector<cv::Mat> grey, depth;
  std::vector<Pose> poses;
  explicit PlaneScene(int frames) {
    cv::Mat tex(200, 260, CV_8U);
    cv::RNG rng(11);
    rng.fill(tex, cv::RNG::UNIFORM, 0, 256);
    cv::GaussianBlur(tex, tex, cv::Size(0, 0), 1.5);
    cv::normalize(tex, tex, 0, 255, cv::NORM_MINMAX);
    for (int k = 0; k < frames; ++k) {
      double shift = K.fx * step * k / Z;
      cv::Mat M = (cv::Mat_<double>(2, 3) << 1, 0, 40 + shift, 0, 1, 40), f;
      cv::warpAffine(tex, f, M, cv::Size(160, 120), cv::INTER_LINEAR | cv::WARP_INVERSE_MAP);
      grey.push_back(f);
      depth.push_back(cv::Mat(120, 160, CV_32F, cv::Scalar(float(Z))));
      Pose p;
      p.t = Eigen::Vector3d(step * k, 0, 0);
      poses.push_back(p);
    }
  }
};

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

// ---- readers ------------------------------------------------------------------------------------

// Writes a demo-layout GT folder and a matching cvd run (depth scaled by 1/s, poses by S^-1).
static void write_scene(const PlaneScene& sc, const fs::path& gt, const fs::path& run, double s) {
  fs::create_directories(gt / "rgb");
  fs::create_directories(gt / "depth");
  fs::create_directories(run / "depth");
  std::vector<TimedPose> gp, rp;
  for (size_t k = 0; k < sc.grey.size(); ++k) {
    std::string name = fmt::format("frame_{:06d}", k);
    cv::Mat bgr;
    cv::cvtColor(sc.grey[k], bgr, cv::COLOR_GRAY2BGR);
    cv::imwrite((gt / "rgb" / (name + ".png")).string(), bgr);
    write_pfm(gt / "depth" / (name + ".pfm"), sc.depth[k]);
    write_pfm(run / "depth" / (name + ".pfm"), cv::Mat(sc.depth[k] / s));
    gp.push_back({k / 30.0, sc.poses[k]});
    Pose p = sc.poses[k];
    p.t /= s;
    rp.push_back({k / 30.0, p});
  }
  write_tum_trajectory(gt / "poses.txt", gp);
  write_tum_trajectory(run / "poses.txt", rp);
  write_intrinsics_json(gt / "intrinsics.json", sc.K);
  write_intrinsics_json(run / "intrinsics.json", sc.K);
  write_text(run / "run.json", "{\"version\": \"test\"}");
}

TEST(EvalReaders, DemoLayoutAndRunAreMatchedByName) {
  test::TempDir tmp;
  PlaneScene sc(4);
  write_scene(sc, tmp / "gt", tmp / "run", 2.0);
  EXPECT_EQ(detect_gt_format(tmp / "gt"), GtFormat::demo);
  EvalSequence gt = read_gt_sequence(tmp / "gt", GtFormat::auto_detect);
  EvalSequence run = read_cvd_run(tmp / "run");
  ASSERT_EQ(gt.frames.size(), 4u);
  EXPECT_TRUE(gt.has_depth() && gt.has_poses() && gt.has_images());
  EXPECT_TRUE(run.has_depth() && run.has_poses());
  EXPECT_EQ(gt.frames[2].name, "frame_000002");
  ASSERT_TRUE(run.intrinsics.has_value());
  EXPECT_DOUBLE_EQ(run.intrinsics->fx, 100);
  // Drop frame 1 from the run: matching is by name, not by index.
  fs::remove(tmp / "run" / "depth" / "frame_000001.pfm");
  write_text(tmp / "run" / "run.json",
             R"({"frames": [{"name": "frame_000000"}, {"name": "frame_000002"},
                            {"name": "frame_000003"}]})");
  EvalSequence gt2 = gt;
  gt2.frames[1].pose.reset();
  std::vector<TimedPose> rp = read_tum_trajectory(tmp / "run" / "poses.txt");
  rp.erase(rp.begin() + 1);
  write_tum_trajectory(tmp / "run" / "poses.txt", rp);
  EvalSequence run2 = read_cvd_run(tmp / "run");
  auto m = match_frames(run2, gt);
  ASSERT_EQ(m.size(), 3u);
  EXPECT_EQ(m[1].gt, 2u);
  EXPECT_EQ(m[1].pred, 1u);
  EXPECT_EQ(run2.frames[1].name, "frame_000002");
  EXPECT_NEAR(run2.frames[1].pose->t.x(), sc.poses[2].t.x() / 2, 1e-6);
  cv::Mat d = load_eval_depth(run2.frames[1]);
  EXPECT_FLOAT_EQ(d.at<float>(5, 5), 1.0f);
}

TEST(EvalReaders, MatchesByTimestampWhenNamesDiffer) {
  EvalSequence pred, gt;
  for (int i = 0; i < 3; ++i) {
    pred.frames.push_back({fmt::format("p{}", i), i * 0.1 + 0.005, {}, 1, {}, std::nullopt});
    gt.frames.push_back({fmt::format("g{}", i), i * 0.1, {}, 1, {}, std::nullopt});
  }
  gt.frames.push_back({"g3", 5.0, {}, 1, {}, std::nullopt});  // no prediction within 20 ms
  auto m = match_frames(pred, gt);
  ASSERT_EQ(m.size(), 3u);
  EXPECT_EQ(m[2].pred, 2u);
  EXPECT_EQ(m[2].gt, 2u);
}

TEST(EvalReaders, RejectMalformedFilesNamingThem) {
  test::TempDir tmp;
  PlaneScene sc(3);
  write_scene(sc, tmp / "gt", tmp / "run", 1.0);
  // A malformed pose line.
  write_text(tmp / "run" / "poses.txt", "0 1 2 3 0 0 0 1\n0.1 1 2 oops\n0.2 0 0 0 0 0 0 1\n");
  expect_error_naming([&] { read_cvd_run(tmp / "run"); }, {"poses.txt"});
  // Pose count does not match the frames.
  write_text(tmp / "run" / "poses.txt", "0 1 2 3 0 0 0 1\n");
  expect_error_naming([&] { read_cvd_run(tmp / "run"); }, {"poses.txt", "1 poses for 3 frames"});
  fs::remove(tmp / "run" / "poses.txt");
  // run.json that is not JSON.
  write_text(tmp / "run" / "run.json", "{ not json");
  expect_error_naming([&] { read_cvd_run(tmp / "run"); }, {"run.json", "JSON"});
  write_text(tmp / "run" / "run.json", "{}");
  // A truncated PFM.
  write_text(tmp / "run" / "depth" / "frame_000000.pfm", "Pf\n160 120\n-1\nabc");
  EvalSequence run = read_cvd_run(tmp / "run");
  expect_error_naming([&] { load_eval_depth(run.frames[0]); }, {"frame_000000.pfm"});
  // No depth at all.
  expect_error_naming([&] { read_cvd_run(tmp / "gt" / "rgb"); }, {"depth"});
  // TUM: bad timestamp in associations.txt, 8-bit depth PNG, bad intrinsics text.
  fs::path tum = tmp / "tum";
  write_text(tum / "associations.txt", "# comment\n0.0 rgb/a.png x depth/a.png\n");
  expect_error_naming([&] { read_gt_sequence(tum, GtFormat::auto_detect); },
                      {"associations.txt:2", "timestamp"});
  write_text(tum / "associations.txt", "0.0 rgb/a.png 0.0 depth/a.png\n");
  fs::create_directories(tum / "depth");
  cv::imwrite((tum / "depth" / "a.png").string(), cv::Mat(4, 4, CV_8U, cv::Scalar(7)));
  EvalSequence ts = read_gt_sequence(tum, GtFormat::tum);
  expect_error_naming([&] { load_eval_depth(ts.frames[0]); }, {"a.png", "16-bit"});
  write_text(tum / "intrinsics_rgb.txt", "# fx fy cx cy w h\n525 525 320\n");
  expect_error_naming([&] { read_gt_sequence(tum, GtFormat::tum); }, {"intrinsics_rgb.txt"});
  EXPECT_THROW(parse_gt_format("kitti"), Error);
}

TEST(EvalReaders, SevenScenesSharedData) {
  CVD_REQUIRE_SHARED_DATA(dir, "7scenes_redkitchen_f000000-000149");
  EXPECT_EQ(detect_gt_format(dir), GtFormat::tum);
  EvalSequence gt = read_gt_sequence(dir, GtFormat::auto_detect);
  ASSERT_EQ(gt.frames.size(), 150u);
  EXPECT_TRUE(gt.has_poses() && gt.has_depth() && gt.has_images());
  EXPECT_EQ(gt.frames[123].name, "frame-000123.color");
  EXPECT_NEAR(*gt.frames[123].timestamp, 4.1, 1e-6);
  ASSERT_TRUE(gt.intrinsics.has_value());
  EXPECT_DOUBLE_EQ(gt.intrinsics->fx, 525.0);
  // First pose line of groundtruth_rgb.txt: t = (-0.3165422, 0.0093614, 0.3024787).
  EXPECT_NEAR(gt.frames[0].pose->t.x(), -0.3165422, 1e-7);
  cv::Mat d = load_eval_depth(gt.frames[0]);
  ASSERT_EQ(d.size(), cv::Size(640, 480));
  double lo, hi;
  cv::minMaxLoc(d, &lo, &hi, nullptr, nullptr, d > 0);
  EXPECT_GT(lo, 0.2);  // metres: a kitchen seen by a Kinect v1
  EXPECT_LT(hi, 8.0);
  EXPECT_GT(cv::countNonZero(d) / double(d.total()), 0.5);  // README: ~72% valid
}

// ---- end to end and report ----------------------------------------------------------------------

TEST(EvalRun, ScaledRunAgainstDemoGt) {
  test::TempDir tmp;
  PlaneScene sc(8);
  write_scene(sc, tmp / "gt", tmp / "run", 2.0);  // the run is the GT at half scale
  EvalRunOptions o;
  o.pred_dir = tmp / "run";
  o.gt_dir = tmp / "gt";
  EvalOutcome r = evaluate_run(o);
  const auto& m = r.metrics;
  EXPECT_EQ(m["frames"]["matched"], 8);
  EXPECT_NEAR(m["depth"]["none"]["depth"]["abs_rel"].get<double>(), 0.5, 1e-6);
  EXPECT_NEAR(m["depth"]["median_frame"]["depth"]["abs_rel"].get<double>(), 0.0, 1e-6);
  EXPECT_NEAR(m["depth"]["median_video"]["disparity"]["abs_rel"].get<double>(), 0.0, 1e-6);
  EXPECT_NEAR(m["pose"]["ate_rmse"].get<double>(), 0.0, 1e-6);
  EXPECT_NEAR(m["pose"]["sim3"]["scale"].get<double>(), 2.0, 1e-6);
  ASSERT_FALSE(m["consistency"].contains("skipped")) << m["consistency"].dump();
  EXPECT_LT(m["consistency"]["flow_reprojection_px"].get<double>(), 0.5);  // DIS on exact motion
  EXPECT_LT(m["consistency"]["instability"].get<double>(), 0.005);         // run units (1 m plane)
  EXPECT_EQ(r.thumbnails.size(), 8u);  // 4 frames x (GT, prediction)
  write_eval_outputs(tmp / "out", r);
  std::ifstream in(tmp / "out" / "metrics.json");
  nlohmann::json back = nlohmann::json::parse(in);
  EXPECT_EQ(back["depth"]["lstsq_frame"]["depth"]["frames"], 8);
  // No GT: only the consistency section.
  EvalRunOptions ng;
  ng.pred_dir = tmp / "run";
  ng.frames_dir = tmp / "gt" / "rgb";
  EvalOutcome r2 = evaluate_run(ng);
  EXPECT_FALSE(r2.metrics.contains("depth"));
  EXPECT_FALSE(r2.metrics.contains("pose"));
  EXPECT_TRUE(r2.metrics["consistency"].contains("instability"));
}

// The run's sparse points: read from sparse_depth.csv.gz (what runs write), or from the
// uncompressed sparse_depth.csv of older runs when that is all there is.
TEST(EvalRun, SparsePointsCompressedOrFromOlderRuns) {
  test::TempDir tmp;
  PlaneScene sc(4);
  write_scene(sc, tmp / "gt", tmp / "run", 2.0);
  // Points on the run's own depth (half the GT's): exact up to the one scale.
  std::map<std::string, SparseDepthFrame> pts;
  for (size_t k = 0; k < sc.depth.size(); ++k) {
    SparseDepthFrame& f = pts[fmt::format("frame_{:06d}", k)];
    f.width = sc.depth[k].cols, f.height = sc.depth[k].rows;
    for (int y = 2; y < f.height; y += 7)
      for (int x = 3; x < f.width; x += 9)
        f.points.push_back({double(x), double(y), sc.depth[k].at<float>(y, x) / 2.0});
  }
  // An older file with a wrong point in every frame: used only when it is the only file.
  std::map<std::string, SparseDepthFrame> old = pts;
  for (auto& [name, f] : old) f.points.front().z *= 3;
  write_sparse_depth_csv(tmp / "run" / kSparseDepthFileUncompressed, old);
  EvalRunOptions o;
  o.pred_dir = tmp / "run";
  o.gt_dir = tmp / "gt";
  const EvalOutcome from_old = evaluate_run(o);
  ASSERT_TRUE(from_old.metrics.contains("sparse"));
  EXPECT_GT(from_old.metrics["sparse"]["abs_rel"].get<double>(), 1e-3);
  write_sparse_depth_csv(tmp / "run" / kSparseDepthFile, pts);
  const EvalOutcome r = evaluate_run(o);
  ASSERT_TRUE(r.metrics.contains("sparse"));
  EXPECT_EQ(r.metrics["sparse"]["frames"], 4);
  EXPECT_NEAR(r.metrics["sparse"]["abs_rel"].get<double>(), 0.0, 1e-6);
  EXPECT_NEAR(r.metrics["sparse"]["abs_rel_video"].get<double>(), 0.0, 1e-6);
}

TEST(EvalRun, SevenScenesGtAtHalfScale) {
  // A run made from the real GT itself at half scale (holes filled with 1 m): exercises the TUM
  // path end to end (names with dots, timestamps, 16-bit PNG depth, 2-D/3-D on real images).
  CVD_REQUIRE_SHARED_DATA(dir, "7scenes_redkitchen_f000000-000149");
  test::TempDir tmp;
  EvalSequence gt = read_gt_sequence(dir, GtFormat::tum);
  const int n = 8;
  std::vector<TimedPose> poses;
  fs::create_directories(tmp / "run" / "depth");
  for (int i = 0; i < n; ++i) {
    cv::Mat d = load_eval_depth(gt.frames[i]) * 0.5;
    d.setTo(1.0f, d <= 0);
    write_pfm(tmp / "run" / "depth" / (gt.frames[i].name + ".pfm"), d);
    Pose p = *gt.frames[i].pose;
    p.t *= 0.5;
    poses.push_back({*gt.frames[i].timestamp, p});
  }
  write_tum_trajectory(tmp / "run" / "poses.txt", poses);
  write_intrinsics_json(tmp / "run" / "intrinsics.json", *gt.intrinsics);
  EvalRunOptions o;
  o.pred_dir = tmp / "run";
  o.gt_dir = dir;
  o.depth.max_depth = 10;
  EvalOutcome r = evaluate_run(o);
  const auto& m = r.metrics;
  EXPECT_EQ(m["frames"]["matched"], n);
  EXPECT_NEAR(m["depth"]["none"]["depth"]["abs_rel"].get<double>(), 0.5, 1e-6);
  EXPECT_NEAR(m["depth"]["median_frame"]["depth"]["abs_rel"].get<double>(), 0.0, 1e-6);
  EXPECT_NEAR(m["depth"]["median_video"]["depth"]["delta1"].get<double>(), 1.0, 1e-9);
  EXPECT_NEAR(m["pose"]["ate_rmse"].get<double>(), 0.0, 1e-6);
  EXPECT_NEAR(m["pose"]["sim3"]["scale"].get<double>(), 2.0, 1e-6);
  ASSERT_TRUE(m["consistency"].contains("instability")) << m["consistency"].dump();
  EXPECT_GT(m["consistency"]["tracks"].get<int>(), 100);
  // Measured depth + KinectFusion poses are consistent to ~1 cm (README: 4-8 mm median |dz|),
  // i.e. ~5 mm at half scale; allow 3 cm. Reprojection vs DIS flow: a few pixels at most.
  EXPECT_LT(m["consistency"]["instability"].get<double>(), 0.03);
  EXPECT_LT(m["consistency"]["drift"].get<double>(), 0.06);
  EXPECT_LT(m["consistency"]["flow_reprojection_px"].get<double>(), 3.0);
}

TEST(EvalRun, CliWritesOutputsAndRejectsBadInput) {
  test::TempDir tmp;
  PlaneScene sc(5);
  write_scene(sc, tmp / "gt", tmp / "run", 1.0);
  auto ok = test::run_cvd(fmt::format("eval --pred {} --gt {} --out {} --max-depth 10",
                                      (tmp / "run").string(), (tmp / "gt").string(),
                                      (tmp / "out").string()));
  ASSERT_EQ(ok.exit_code, 0) << ok.output;
  EXPECT_TRUE(fs::exists(tmp / "out" / "metrics.json"));
  EXPECT_TRUE(fs::exists(tmp / "out" / "report.html"));
  for (auto& e : fs::directory_iterator(tmp / "out"))  // atomic writes leave no temporaries
    EXPECT_EQ(e.path().filename().string()[0] != '.', true) << e.path();
  write_text(tmp / "run" / "poses.txt", "garbage\n");
  auto bad = test::run_cvd(fmt::format("eval --pred {}", (tmp / "run").string()));
  EXPECT_EQ(bad.exit_code, 3) << bad.output;  // kExitBadInput
  EXPECT_NE(bad.output.find("poses.txt"), std::string::npos) << bad.output;
}

TEST(EvalReport, Base64AndSvg) {
  EXPECT_EQ(base64_encode({'M', 'a', 'n'}), "TWFu");
  EXPECT_EQ(base64_encode({'M', 'a'}), "TWE=");
  EXPECT_EQ(base64_encode({'M'}), "TQ==");
  std::string svg = svg_line_plot("t<1>", "x", "y", {{"a", {0, 1, 2}, {1, 4, NAN}}});
  EXPECT_NE(svg.find("<svg"), std::string::npos);
  EXPECT_NE(svg.find("t&lt;1&gt;"), std::string::npos);  // escaped title
  EXPECT_NE(svg.find("<polyline"), std::string::npos);
}

TEST(EvalReport, RendersInHeadlessChromium) {
  if (std::system("command -v chromium > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "chromium not installed (scripts/install-deps.sh installs it)";
  test::TempDir tmp;
  PlaneScene sc(6);
  write_scene(sc, tmp / "gt", tmp / "run", 2.0);
  EvalRunOptions o;
  o.pred_dir = tmp / "run";
  o.gt_dir = tmp / "gt";
  write_eval_outputs(tmp / "out", evaluate_run(o));
  std::string cmd = fmt::format(
      "chromium --headless --no-sandbox --disable-gpu --disable-background-networking "
      "--user-data-dir={} --dump-dom file://{}",
      (tmp / "profile").string(), (tmp / "out" / "report.html").string());
  auto r = test::run_command(cmd);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // The DOM as Chromium parsed it: the SVG plots, the tables and the inline thumbnails.
  auto count = [&](const std::string& s) {
    size_t n = 0;
    for (size_t p = r.output.find(s); p != std::string::npos; p = r.output.find(s, p + 1)) ++n;
    return n;
  };
  EXPECT_GE(count("<svg"), 7u);  // 2x2 depth plots, trajectory, ATE, flow pairs
  EXPECT_GE(count("<polyline"), 7u);
  EXPECT_GE(count("data:image/png;base64,"), 9u);  // 8 thumbnails and their colour bar
  EXPECT_NE(r.output.find("Sorted per-pixel AbsRel"), std::string::npos);
  EXPECT_NE(r.output.find("Trajectory, top view"), std::string::npos);
  // The plots hold the aligned rows only (the unaligned ones set the axis and flattened them).
  EXPECT_EQ(r.output.find(">none</text>"), std::string::npos);
  EXPECT_NE(r.output.find(">median_frame</text>"), std::string::npos);
  EXPECT_NE(r.output.find("depth colour bar"), std::string::npos);

  // And as a person sees it: a screenshot with the plots' lines and the turbo thumbnails. The
  // screenshot waits for the page to settle (its inline images decoded and painted): without
  // that, a CI run on a busy machine caught it before the thumbnails were drawn (89 colours,
  // 0.1% saturated).
  const fs::path shot = tmp / "report.png";
  auto s = test::run_command(fmt::format(
      "chromium --headless --no-sandbox --disable-gpu --disable-background-networking "
      "--hide-scrollbars --run-all-compositor-stages-before-draw --virtual-time-budget=10000 "
      "--user-data-dir={} --window-size=1200,2400 --screenshot={} file://{}",
      (tmp / "profile2").string(), shot.string(), (tmp / "out" / "report.html").string()));
  ASSERT_EQ(s.exit_code, 0) << s.output;
  const cv::Mat img = cv::imread(shot.string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(img.empty()) << s.output;
  // Distinct colours: a blank or text-only page has a few dozen greys at most; lines, legends
  // and colour-mapped thumbnails give more than a hundred (measured: 191). Saturated pixels
  // (the turbo thumbnails and their colour bar) cover over 1% of the page (measured: 2.0%).
  std::set<int> colours;
  size_t saturated = 0, sampled = 0;
  for (int y = 0; y < img.rows; y += 2)
    for (int x = 0; x < img.cols; x += 2) {
      const cv::Vec3b p = img.at<cv::Vec3b>(y, x);
      colours.insert((p[0] >> 3) << 10 | (p[1] >> 3) << 5 | (p[2] >> 3));
      const int hi = std::max({p[0], p[1], p[2]}), lo = std::min({p[0], p[1], p[2]});
      saturated += hi - lo > 100;
      ++sampled;
    }
  EXPECT_GT(colours.size(), 100u);
  EXPECT_GT(double(saturated) / double(sampled), 0.01);
  std::printf("[report screenshot] %zu colours, %.1f%% saturated pixels\n", colours.size(),
              100.0 * double(saturated) / double(sampled));
}
