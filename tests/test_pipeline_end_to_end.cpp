// The whole pipeline on a small generated scene with known depth and poses: test-time training
// must lower both the geometric (flow-reprojection) loss and the depth error against the ground
// truth, by margins measured on this configuration (see the numbers below).
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "pipeline/eval/eval_depth_metrics.h"
#include "pipeline/io/pfm_io.h"
#include "pipeline/io/trajectory_io.h"
#include "pipeline/run/run_pipeline.h"
#include "scene/synthetic_scene.h"
#include "test_support.h"

namespace cvd {
namespace {

namespace fs = std::filesystem;

// The generated scene, `frames` frames of 256x160, written to dir/scene; its ground truth.
SceneGroundTruth write_scene(const fs::path& dir, int frames) {
  SyntheticSceneOptions so;
  so.frames = frames;
  so.width = 256;
  so.height = 160;
  write_synthetic_scene(render_synthetic_scene(so), dir / "scene");
  return read_scene_ground_truth(dir / "scene");
}

// A run of dir/scene/rgb with given poses and the scene's intrinsics, no videos or point cloud.
RunOptions scene_run(const fs::path& dir, const SceneGroundTruth& gt, const fs::path& poses,
                     const fs::path& out) {
  RunOptions o;
  o.input = dir / "scene" / "rgb";
  o.out = out;
  o.poses_file = poses;
  o.poses_format = "tum";
  o.intrinsics = gt.intrinsics;
  o.width = 0.125;
  o.write_videos = false;
  o.write_point_cloud = false;
  return o;
}

TEST(PipelineEndToEnd, TrainingLowersFlowReprojectionLossAndDepthErrorOnTheSyntheticScene) {
  test::TempDir dir;
  SceneGroundTruth gt = write_scene(dir.path(), 8);
  RunOptions o = scene_run(dir.path(), gt, dir / "scene" / "poses.txt", dir / "run");
  o.depth_long_side = 128;
  o.epochs = 3;
  o.warmup_steps = 40;
  RunResult r = run_pipeline(o);
  ASSERT_EQ(r.frame_names.size(), 8u);
  ASSERT_GT(r.num_pairs, 8);

  std::vector<cv::Mat> gts, init, fin;
  for (size_t k = 0; k < gt.frames.size(); ++k) {
    gts.push_back(gt.frames[k].depth);
    cv::Mat a = read_pfm(o.out / "depth_initial" / (r.frame_names[k] + ".pfm")), b;
    cv::resize(a, a, gts.back().size(), 0, 0, cv::INTER_LINEAR);
    cv::resize(r.depths[k], b, gts.back().size(), 0, 0, cv::INTER_LINEAR);
    init.push_back(a);
    fin.push_back(b);
  }
  DepthEvalOptions eo;
  double abs_rel0 =
      evaluate_video_depth(init, gts, DepthAlignment::median_frame, DepthSpace::depth, eo)
          .mean.abs_rel;
  double abs_rel1 =
      evaluate_video_depth(fin, gts, DepthAlignment::median_frame, DepthSpace::depth, eo)
          .mean.abs_rel;
  RecordProperty("abs_rel_initial", std::to_string(abs_rel0));
  RecordProperty("abs_rel_final", std::to_string(abs_rel1));
  RecordProperty("loss_initial", std::to_string(r.initial_loss));
  RecordProperty("loss_final", std::to_string(r.final_loss));
  // Measured on this configuration (2-core VM, 2026-12-06, lambda 0.01 in units of the median
  // sparse depth): AbsRel 0.208 -> 0.138 (-34%), geometric loss 1.191 -> 0.837 (-30%; three
  // short epochs; with lambda 0.1 in metres before the depth unit: 0.183 -> 0.149, 1.280 ->
  // 1.249). Margins: at least 10% lower AbsRel and 1% lower
  // loss; an untrained network stays at the initial values and a diverging one goes above them.
  EXPECT_LT(abs_rel1, 0.90 * abs_rel0) << "initial " << abs_rel0 << " final " << abs_rel1;
  EXPECT_LT(r.final_loss, 0.99 * r.initial_loss)
      << "initial " << r.initial_loss << " final " << r.final_loss;
  ASSERT_EQ(r.epoch_losses.size(), 3u);
  for (double l : r.epoch_losses) EXPECT_TRUE(std::isfinite(l));
}

// The unit of given poses does not change what training does: the same scene with its camera
// centres in millimetres instead of metres gives the same depth maps, in millimetres. The loss
// measures its disparity term in the median sparse depth (GeometricLossOptions::depth_unit);
// with a fixed unit the disparity term would weigh 1000 times less in millimetres. No warm-up:
// its first Adam steps follow gradients that are rounding noise, which f32 rounds differently
// in the two units; the flat start gives the lower layers no gradient until the head has one.
TEST(PipelineEndToEnd, GivenPosesInMillimetresGiveTheSameDepthInMillimetres) {
  test::TempDir dir;
  SceneGroundTruth gt = write_scene(dir.path(), 6);
  const double k = 1000.0;
  std::vector<TimedPose> poses = read_tum_trajectory(dir / "scene" / "poses.txt");
  for (TimedPose& p : poses) p.pose.t *= k;
  write_tum_trajectory(dir / "poses_mm.txt", poses);

  auto run = [&](const fs::path& poses_file, const char* out) {
    RunOptions o = scene_run(dir.path(), gt, poses_file, dir / out);
    o.depth_long_side = 96;
    o.epochs = 2;
    o.warmup_steps = 0;
    o.lambda_disparity = 0.1;  // a disparity term ten times the default's: a unit error shows
    return run_pipeline(o);
  };
  RunResult m = run(dir / "scene" / "poses.txt", "metres");
  RunResult mm = run(dir / "poses_mm.txt", "millimetres");
  ASSERT_EQ(m.depths.size(), mm.depths.size());
  // The loss is in pixels (and disparity in depth units): the same value in both units.
  EXPECT_NEAR(mm.initial_loss, m.initial_loss, 1e-6 * m.initial_loss);
  double sum = 0, worst = 0;
  size_t count = 0;
  for (size_t f = 0; f < m.depths.size(); ++f) {
    cv::Mat ratio;
    cv::divide(mm.depths[f], m.depths[f] * k, ratio);
    cv::log(ratio, ratio);
    ratio = cv::abs(ratio);
    sum += cv::sum(ratio)[0];
    count += ratio.total();
    double lo = 0, hi = 0;
    cv::minMaxLoc(ratio, &lo, &hi);
    worst = std::max(worst, hi);
  }
  const double mean = sum / static_cast<double>(count);
  RecordProperty("mean_abs_log_ratio", std::to_string(mean));
  RecordProperty("max_abs_log_ratio", std::to_string(worst));
  // Measured (2026-12-06): mean |log ratio| 8.8e-5, max 4.1e-4 (f32 rounding). What a fixed
  // unit would give (the millimetre run with lambda / 1000, 1e-4): mean 2.2e-3, max 4.1e-3, and
  // a geometric loss before training of 1.43 against 1.77.
  EXPECT_LT(mean, 4e-4);
  EXPECT_LT(worst, 2e-3);
}

}  // namespace
}  // namespace cvd
