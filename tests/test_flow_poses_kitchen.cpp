// Cameras from optical flow on the shared real clip (7-Scenes kitchen; ../shared/data), against
// its ground truth: known intrinsics, and the focal estimated by the flow adjustment. Slow (a
// minute); skipped, saying why, without the shared data.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>

#include "pipeline/eval/eval_pose_metrics.h"
#include "pipeline/io/trajectory_io.h"
#include "pipeline/poses/flow_poses.h"

namespace fs = std::filesystem;
using namespace cvd;

namespace {

const fs::path kKitchen = fs::path(CVD_SHARED_DIR) / "data/7scenes_redkitchen_f000000-000149";

struct Clip {
  std::vector<std::string> names;
  std::vector<fs::path> files;
  std::vector<Pose> gt;
};

Clip kitchen(int count, int step) {
  Clip c;
  const std::vector<TimedPose> traj = read_tum_trajectory(kKitchen / "groundtruth_rgb.txt");
  for (int k = 0; k < count; ++k) {
    char name[64];
    std::snprintf(name, sizeof name, "frame-%06d.color", k * step);
    c.names.push_back(name);
    c.files.push_back(kKitchen / "rgb" / (std::string(name) + ".jpg"));
    c.gt.push_back(traj.at(size_t(k * step)).pose);
  }
  return c;
}

std::vector<Pose> poses_of(const FlowPoseResult& r) {
  std::vector<Pose> p;
  for (const auto& c : r.cameras) p.push_back(c.pose);
  return p;
}

}  // namespace

// Frames 0-149 every 3rd (50 frames; the clip with parallax): COLMAP reaches ATE 1.7 cm here.
TEST(FlowPosesKitchen, Every3rdFrameWithinTwoAndAHalfCentimetresAndTheFocalWithinTenPercent) {
  if (!fs::exists(kKitchen / "rgb"))
    GTEST_SKIP() << kKitchen << " not found (the shared data; see ../shared/data/README.md)";
  const Clip c = kitchen(50, 3);
  auto frame = [&](size_t k) { return cv::imread(c.files[k].string()); };
  const Intrinsics K{525, 525, 320, 240, 640, 480};
  const FlowPoseResult known = estimate_flow_poses(c.names, frame, nullptr, K);
  EXPECT_TRUE(known.unregistered.empty());
  const PoseErrors e = absolute_trajectory_error(poses_of(known), c.gt);
  std::printf("known intrinsics: ATE %.2f cm, %d points, RMS %.2f px, %.0f s\n", 100 * e.ate_rmse,
              known.points, known.rms_px, known.seconds);
  EXPECT_LT(e.ate_rmse, 0.025);

  const FlowPoseResult estimated = estimate_flow_poses(c.names, frame, nullptr, std::nullopt);
  const double focal = estimated.cameras.front().intrinsics.fx;
  const PoseErrors e2 = absolute_trajectory_error(poses_of(estimated), c.gt);
  std::printf("estimated focal %.1f px (true 525), ATE %.2f cm\n", focal, 100 * e2.ate_rmse);
  EXPECT_NEAR(focal / 525.0, 1.0, 0.10);
  EXPECT_LT(e2.ate_rmse, 0.04);
}

// Frames 0-39 (little parallax: 9% of the width in 40 frames): COLMAP's ATE is 0.4-0.5 cm, its
// rotations 1.5 degrees off over 10 frames.
TEST(FlowPosesKitchen, First40FramesPosedWithRotationsBetterThanADegreeOverTenFrames) {
  if (!fs::exists(kKitchen / "rgb"))
    GTEST_SKIP() << kKitchen << " not found (the shared data; see ../shared/data/README.md)";
  const Clip c = kitchen(40, 1);
  auto frame = [&](size_t k) { return cv::imread(c.files[k].string()); };
  const Intrinsics K{525, 525, 320, 240, 640, 480};
  const FlowPoseResult r = estimate_flow_poses(c.names, frame, nullptr, K);
  EXPECT_TRUE(r.unregistered.empty());
  const PoseErrors e = absolute_trajectory_error(poses_of(r), c.gt);
  const RelativePoseErrors rpe = relative_pose_error(poses_of(r), c.gt, 10, e.alignment);
  std::printf("ATE %.2f cm, RPE rotation @10 %.3f deg\n", 100 * e.ate_rmse, rpe.rot_mean_deg);
  EXPECT_LT(rpe.rot_mean_deg, 1.0);
  EXPECT_LT(e.ate_rmse, 0.04);

  const FlowPoseResult estimated = estimate_flow_poses(c.names, frame, nullptr, std::nullopt);
  const double focal = estimated.cameras.front().intrinsics.fx;
  std::printf("estimated focal %.1f px (true 525)\n", focal);
  // Measured 570 px (every rerun the same; frames 0-149/3 give 570 px too: the flow's own
  // answer, 8.6% above the nominal 525); the target is 10%.
  EXPECT_NEAR(focal / 525.0, 1.0, 0.10);
  for (const auto& cand : estimated.candidates)
    std::printf("  from %.0f deg, %s: focal %.1f px, score %.4g\n", cand.start_fov_deg,
                cand.rotations.c_str(), cand.focal_px, cand.score);
}
