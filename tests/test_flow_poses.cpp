// Cameras from optical flow (pipeline/poses/flow_poses.h) and its parts.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <random>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <fstream>

#include "engine/error.h"
#include "pipeline/eval/eval_pose_metrics.h"
#include "pipeline/io/trajectory_io.h"
#include "pipeline/poses/flow_camera_init.h"
#include "pipeline/poses/flow_poses.h"
#include "pipeline/poses/track_bundle_adjustment.h"
#include "scene/synthetic_scene.h"
#include "tests/test_support.h"

namespace fs = std::filesystem;
using namespace cvd;

namespace {

double rotation_angle_deg(const Eigen::Matrix3d& A, const Eigen::Matrix3d& B) {
  return Eigen::AngleAxisd(A.transpose() * B).angle() * 180.0 / M_PI;
}

// A camera path looking down +z at points 3-6 m ahead, with rotations of a few degrees, and the
// tracks of those points (every point seen by every camera it projects into, in runs of
// consecutive frames), with Gaussian pixel noise and a fraction of gross outliers.
struct SyntheticTracks {
  TrackCameras truth;
  std::vector<Eigen::Vector3d> points;
  std::vector<PixelTrack> tracks;
};

SyntheticTracks synthetic_tracks(int frames, int num_points, double noise_px, double outliers,
                                 uint32_t seed = 3) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, noise_px);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  SyntheticTracks s;
  TrackCameras& c = s.truth;
  c.width = 320;
  c.height = 240;
  c.focal = 280;
  c.cx = 159.5;
  c.cy = 119.5;
  for (int k = 0; k < frames; ++k) {
    const double a = 0.05 * k;
    c.R.push_back((Eigen::AngleAxisd(0.04 * std::sin(a), Eigen::Vector3d::UnitX()) *
                   Eigen::AngleAxisd(0.08 * a, Eigen::Vector3d::UnitY()))
                      .toRotationMatrix());
    c.c.push_back(Eigen::Vector3d(0.05 * k, 0.01 * std::sin(2 * a), 0.01 * k));
  }
  for (int i = 0; i < num_points; ++i)
    s.points.push_back(Eigen::Vector3d(3 * u(rng), 1.5 * u(rng), 4.5 + 1.5 * u(rng)));
  for (const Eigen::Vector3d& X : s.points) {
    PixelTrack t;
    for (int k = 0; k < frames; ++k) {
      const Eigen::Vector3d p = c.R[size_t(k)].transpose() * (X - c.c[size_t(k)]);
      const double x = c.focal * p.x() / p.z() + c.cx, y = c.focal * p.y() / p.z() + c.cy;
      const bool inside = p.z() > 0 && x >= 0 && y >= 0 && x < c.width && y < c.height;
      if (!inside) {
        if (t.observations.size() >= 3) s.tracks.push_back(t);
        t.observations.clear();
        continue;
      }
      const bool outlier = (u(rng) + 1) / 2 < outliers;
      t.observations.push_back(
          {k, x + (outlier ? 15 * u(rng) : noise(rng)), y + (outlier ? 15 * u(rng) : noise(rng))});
    }
    if (t.observations.size() >= 3) s.tracks.push_back(t);
  }
  return s;
}

// Rotations and centres relative to frame 0 (the gauge every estimate here uses).
TrackCameras relative_to_first(const TrackCameras& c) {
  TrackCameras r = c;
  for (size_t k = 0; k < c.R.size(); ++k) {
    r.R[k] = c.R[0].transpose() * c.R[k];
    r.c[k] = c.R[0].transpose() * (c.c[k] - c.c[0]);
  }
  return r;
}

// Largest rotation error (degrees) and RMS centre error after the best scale, relative to the
// RMS centre distance, of `est` against `truth`, both relative to their first frame.
std::pair<double, double> camera_errors(const TrackCameras& est_in, const TrackCameras& truth_in) {
  const TrackCameras est = relative_to_first(est_in), truth = relative_to_first(truth_in);
  double rot = 0, dot = 0, norm = 0, truth_norm = 0;
  for (size_t k = 0; k < est.R.size(); ++k) {
    rot = std::max(rot, rotation_angle_deg(est.R[k], truth.R[k]));
    dot += est.c[k].dot(truth.c[k]);
    norm += est.c[k].squaredNorm();
    truth_norm += truth.c[k].squaredNorm();
  }
  const double scale = norm > 0 ? dot / norm : 0;
  double err = 0;
  for (size_t k = 0; k < est.R.size(); ++k) err += (scale * est.c[k] - truth.c[k]).squaredNorm();
  return {rot, std::sqrt(err / truth_norm)};
}

}  // namespace

TEST(FlowCameraInit, ExactTracksGiveExactRotationsAndCentresUpToScale) {
  SyntheticTracks s = synthetic_tracks(12, 400, 0.0, 0.0);
  std::vector<bool> usable(12, true);
  TrackCameras est = s.truth;
  EXPECT_EQ(chain_rotations(s.tracks, usable, est), 0);
  ASSERT_TRUE(centres_from_rotations(s.tracks, usable, est));
  const auto [rot, centre] = camera_errors(est, s.truth);
  EXPECT_LT(rot, 0.01);     // degrees; measured ~1e-6
  EXPECT_LT(centre, 1e-3);  // relative; measured ~1e-7
  // Every intersected point in front of the cameras; none to move.
  std::vector<Eigen::Vector3d> X = intersect_track_rays(s.tracks, usable, est);
  EXPECT_EQ(place_points_in_front(s.tracks, usable, est, X), 0);
}

TEST(FlowCameraInit, PointsBehindACameraAreMovedOntoTheRayInFront) {
  SyntheticTracks s = synthetic_tracks(6, 50, 0.0, 0.0);
  std::vector<bool> usable(6, true);
  std::vector<Eigen::Vector3d> X = s.points;
  std::vector<Eigen::Vector3d> at_tracks;
  for (const auto& t : s.tracks) {
    (void)t;
    at_tracks.push_back(Eigen::Vector3d(0, 0, -5));  // behind every camera
  }
  const int moved = place_points_in_front(s.tracks, usable, s.truth, at_tracks);
  EXPECT_EQ(moved, static_cast<int>(s.tracks.size()));
  for (size_t t = 0; t < s.tracks.size(); ++t) {
    const auto& ob = s.tracks[t].observations.front();
    EXPECT_LT(reprojection_error_px(s.truth, at_tracks[t], ob), 1e-6);
  }
}

TEST(TrackBundleAdjustment, RecoversCamerasAndFocalFromNoisyTracksWithOutliers) {
  // 0.3 px noise; then the same with 5% gross outliers (uniform within +-15 px), which the
  // second pass leaves out. Start: rotations chained from the tracks, centres solved given them,
  // focal 15% long.
  for (const double outliers : {0.0, 0.05}) {
    SCOPED_TRACE(fmt::format("outlier fraction {}", outliers));
    SyntheticTracks s = synthetic_tracks(16, 600, 0.3, outliers);
    std::vector<bool> usable(16, true);
    TrackCameras est = s.truth;
    est.focal *= 1.15;
    chain_rotations(s.tracks, usable, est);
    ASSERT_TRUE(centres_from_rotations(s.tracks, usable, est));
    std::vector<Eigen::Vector3d> X = intersect_track_rays(s.tracks, usable, est);
    place_points_in_front(s.tracks, usable, est, X);
    TrackBundleOptions o;
    o.refine_focal = true;
    o.threads = 2;
    const TrackBundleReport r = bundle_adjust_tracks(s.tracks, usable, X, est, o);
    ASSERT_TRUE(r.usable);
    EXPECT_LT(r.final_cost, r.initial_cost);
    // Measured: 0.2% without outliers, 2.7% with (the outliers within 3 px stay in).
    EXPECT_NEAR(est.focal / s.truth.focal, 1.0, outliers > 0 ? 0.04 : 0.01);
    if (outliers > 0) {
      EXPECT_GT(r.outliers, 0);
    }
    const auto [rot, centre] = camera_errors(est, s.truth);
    EXPECT_LT(rot, 0.1);      // degrees
    EXPECT_LT(centre, 0.02);  // relative to the path's RMS distance
    // The frame held fixed did not move.
    EXPECT_LT(rotation_angle_deg(est.R[0], s.truth.R[0]), 1e-9);
    EXPECT_LT((est.c[0] - s.truth.c[0]).norm(), 1e-9);
  }
}

TEST(TrackBundleAdjustment, MismatchedSizesAreAnError) {
  SyntheticTracks s = synthetic_tracks(4, 20, 0.0, 0.0);
  std::vector<Eigen::Vector3d> X(s.tracks.size() + 1);
  std::vector<bool> usable(4, true);
  EXPECT_THROW(bundle_adjust_tracks(s.tracks, usable, X, s.truth), cvd::Error);
}

namespace {

// The generated scene (no moving object), small, written to `dir`.
SceneGroundTruth generated_clip(const fs::path& dir, int frames) {
  SyntheticSceneOptions so;
  so.width = 256;
  so.height = 160;
  so.frames = frames;
  so.moving_object = false;
  so.supersampling = 1;
  write_synthetic_scene(render_synthetic_scene(so), dir);
  return read_scene_ground_truth(dir);
}

// A generated clip's frame names, true poses and path length (sum of the centre steps).
struct ClipFrames {
  std::vector<std::string> names;
  std::vector<Pose> poses;
  double path = 0;
};
ClipFrames frames_of(const SceneGroundTruth& gt) {
  ClipFrames c;
  for (const auto& f : gt.frames) {
    c.names.push_back(f.name);
    c.poses.push_back(f.pose);
  }
  for (size_t k = 1; k < c.poses.size(); ++k) c.path += (c.poses[k].t - c.poses[k - 1].t).norm();
  return c;
}

std::vector<Pose> poses_of(const std::vector<NamedCamera>& cams) {
  std::vector<Pose> p;
  for (const auto& c : cams) p.push_back(c.pose);
  return p;
}

}  // namespace

TEST(FlowPoses, GeneratedSceneCamerasAndFocalFromFlowAlone) {
  test::TempDir dir;
  const SceneGroundTruth gt = generated_clip(dir.path(), 24);
  const auto& [names, gt_poses, path] = frames_of(gt);
  auto frame = [&](size_t k) { return cv::imread(gt.frames[k].rgb_path.string()); };
  FlowPoseOptions o;
  o.max_tracks = 4000;
  o.candidate_tracks = 1500;

  // Known intrinsics.
  const FlowPoseResult known = estimate_flow_poses(names, frame, nullptr, gt.intrinsics, o);
  ASSERT_EQ(known.cameras.size(), names.size());
  EXPECT_TRUE(known.unregistered.empty());
  EXPECT_EQ(known.focal_method, "given");
  const PoseErrors e = absolute_trajectory_error(poses_of(known.cameras), gt_poses);
  EXPECT_LT(e.ate_rmse, 0.02 * path) << "ATE " << e.ate_rmse << " m over a " << path << " m path";
  const RelativePoseErrors rpe =
      relative_pose_error(poses_of(known.cameras), gt_poses, 1, e.alignment);
  EXPECT_LT(rpe.rot_mean_deg, 0.1);
  EXPECT_GT(known.points, 100);
  EXPECT_LT(known.rms_px, 1.0);
  // The model holds the same cameras and the points with their observations.
  EXPECT_EQ(known.model.images.size(), names.size());
  EXPECT_EQ(static_cast<int>(known.model.points.size()), known.points);
  EXPECT_FALSE(known.model.observed_points(names[3]).empty());

  // Unknown intrinsics: the focal comes out of the adjustment of the best candidate.
  const FlowPoseResult estimated = estimate_flow_poses(names, frame, nullptr, std::nullopt, o);
  EXPECT_EQ(estimated.focal_method, "flow bundle adjustment");
  EXPECT_EQ(estimated.candidates.size(), 2 * o.candidate_fov_deg.size());  // x 2 rotation starts
  EXPECT_NEAR(estimated.cameras[0].intrinsics.fx / gt.intrinsics.fx, 1.0, 0.05);
  // The finalists (adjusted further on every track) carry their final error.
  int finalists = 0;
  for (const auto& c : estimated.candidates) finalists += c.final_score > 0;
  EXPECT_GE(finalists, 1);
  EXPECT_LE(finalists, o.finalists);

  // A rerun gives the same cameras, bit for bit (every adjustment is single-threaded, side by
  // side), whatever the number of threads.
  FlowPoseOptions one_thread = o;
  one_thread.threads = 1;
  const FlowPoseResult again =
      estimate_flow_poses(names, frame, nullptr, gt.intrinsics, one_thread);
  ASSERT_EQ(again.cameras.size(), known.cameras.size());
  for (size_t k = 0; k < again.cameras.size(); ++k) {
    EXPECT_EQ(again.cameras[k].pose.t, known.cameras[k].pose.t) << names[k];
    EXPECT_EQ(again.cameras[k].pose.R, known.cameras[k].pose.R) << names[k];
  }
  EXPECT_EQ(again.points, known.points);
}

TEST(FlowPoses, RunWithoutColmapFallsBackToTheFlowWithAWarning) {
  test::TempDir dir;
  const SceneGroundTruth gt = generated_clip(dir.path() / "scene", 10);
  fs::create_directories(dir.path() / "empty_bin");
  const Intrinsics& K = gt.intrinsics;
  const auto r = test::run_command(fmt::format(
      "PATH='{}' {} run {} -o {} --intrinsics {},{},{},{} --epochs 1 --warmup 1 --width 0.0625 "
      "--depth-size 64 --no-videos",
      (dir.path() / "empty_bin").string(), test::cli_path(), (dir.path() / "scene/rgb").string(),
      (dir.path() / "out").string(), K.fx, K.fy, K.cx, K.cy));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("colmap is not on PATH; cameras come from the optical flow"),
            std::string::npos)
      << r.output;
  std::ifstream in(dir.path() / "out/run.json");
  const nlohmann::json run = nlohmann::json::parse(in);
  EXPECT_EQ(run["poses"]["source"], "flow");
  EXPECT_EQ(run["frame_stats"]["registered"], 10);
  EXPECT_TRUE(fs::exists(dir.path() / "out/poses.txt"));
  // --poses-source colmap keeps COLMAP's error.
  const auto c = test::run_command(fmt::format(
      "PATH='{}' {} run {} -o {} --poses-source colmap --intrinsics {},{},{},{} --epochs 1",
      (dir.path() / "empty_bin").string(), test::cli_path(), (dir.path() / "scene/rgb").string(),
      (dir.path() / "out2").string(), K.fx, K.fy, K.cx, K.cy));
  EXPECT_NE(c.exit_code, 0);
  EXPECT_NE(c.output.find("colmap not found on PATH"), std::string::npos) << c.output;
}

// --given-poses adjusted: the adjustment starts from given cameras (here the true ones in other
// units, perturbed by ~1.5 deg and 3% of the path) and brings them back onto the frames, in the
// given units, with the first camera held and an unregistered frame left unregistered.
TEST(FlowPoses, AdjustedStartRecoversPerturbedCamerasInTheirUnits) {
  test::TempDir dir;
  const SceneGroundTruth gt = generated_clip(dir.path(), 24);
  const auto& [names, gt_poses, path] = frames_of(gt);
  const double units = 2.5;  // the given poses' units: 2.5 per scene metre
  const size_t dropped = 7;  // given as unregistered
  std::mt19937 rng(11);
  std::normal_distribution<double> n01(0.0, 1.0);
  std::vector<NamedCamera> start;
  for (size_t k = 0; k < names.size(); ++k) {
    NamedCamera c;
    c.name = names[k];
    c.intrinsics = gt.intrinsics;
    c.pose.R = gt_poses[k].R;
    c.pose.t = units * gt_poses[k].t;
    if (k > 0) {
      const Eigen::Vector3d axis = Eigen::Vector3d(n01(rng), n01(rng), n01(rng)).normalized();
      c.pose.R = c.pose.R * Eigen::AngleAxisd(1.5 * M_PI / 180.0, axis).toRotationMatrix();
      c.pose.t += units * 0.03 * path * Eigen::Vector3d(n01(rng), n01(rng), n01(rng));
    }
    c.registered = k != dropped;
    start.push_back(c);
  }
  auto frame = [&](size_t k) { return cv::imread(gt.frames[k].rgb_path.string()); };
  FlowPoseOptions o;
  o.max_tracks = 4000;
  const FlowPoseResult r = estimate_flow_poses(names, frame, nullptr, gt.intrinsics, o, &start);
  ASSERT_EQ(r.cameras.size(), names.size());
  EXPECT_EQ(r.focal_method, "given");
  EXPECT_EQ(r.rotation_start, "given poses");
  EXPECT_TRUE(r.candidates.empty());  // no candidate search
  EXPECT_DOUBLE_EQ(r.cameras[0].intrinsics.fx, gt.intrinsics.fx);
  ASSERT_EQ(r.unregistered, std::vector<std::string>{names[dropped]});
  EXPECT_FALSE(r.cameras[dropped].registered);
  // The perturbed start fits the tracks far worse than the adjusted cameras.
  EXPECT_GT(r.start_score_px2, 10 * r.score_px2)
      << "start " << r.start_score_px2 << " px^2, adjusted " << r.score_px2 << " px^2";
  // The first camera is held where it was given.
  EXPECT_LT((r.cameras[0].pose.t - start[0].pose.t).norm(), 1e-9);
  EXPECT_LT(rotation_angle_deg(r.cameras[0].pose.R, start[0].pose.R), 1e-6);

  std::vector<Pose> est, truth, given;
  for (size_t k = 0; k < names.size(); ++k) {
    if (k == dropped) continue;
    est.push_back(r.cameras[k].pose);
    truth.push_back(gt_poses[k]);
    given.push_back(start[k].pose);
  }
  const PoseErrors e = absolute_trajectory_error(est, truth);
  const PoseErrors e_start = absolute_trajectory_error(given, truth);
  EXPECT_LT(e.ate_rmse, 0.01 * path) << "ATE " << e.ate_rmse << " m over a " << path << " m path";
  EXPECT_LT(e.ate_rmse, 0.5 * e_start.ate_rmse);
  // Units kept: the similarity onto the truth (metres) scales by 1 / units (up to the perturbed
  // distance of the farthest camera, which holds the scale: 2% here).
  EXPECT_NEAR(e.alignment.scale * units, 1.0, 0.05);
  const RelativePoseErrors rpe = relative_pose_error(est, truth, 1, e.alignment);
  EXPECT_LT(rpe.rot_mean_deg, 0.1);
  EXPECT_GT(r.points, 100);
  EXPECT_EQ(static_cast<int>(r.model.points.size()), r.points);
}
