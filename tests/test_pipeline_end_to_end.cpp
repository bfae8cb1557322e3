// The whole pipeline on a small generated scene with known depth and poses: test-time training
// must lower both the geometric (flow-reprojection) loss and the depth error against the ground
// truth, by margins measured on this configuration (see the numbers below).
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "pipeline/eval/eval_depth_metrics.h"
#include "pipeline/io/pfm_io.h"
#include "pipeline/run/run_pipeline.h"
#include "scene/synthetic_scene.h"
#include "test_support.h"

namespace cvd {
namespace {

namespace fs = std::filesystem;

TEST(PipelineEndToEnd, TrainingLowersFlowReprojectionLossAndDepthErrorOnTheSyntheticScene) {
  test::TempDir dir;
  SyntheticSceneOptions so;
  so.frames = 8;
  so.width = 256;
  so.height = 160;
  write_synthetic_scene(render_synthetic_scene(so), dir / "scene");
  SceneGroundTruth gt = read_scene_ground_truth(dir / "scene");

  RunOptions o;
  o.input = dir / "scene" / "rgb";
  o.out = dir / "run";
  o.poses_file = dir / "scene" / "poses.txt";
  o.poses_format = "tum";
  o.intrinsics = gt.intrinsics;
  o.depth_long_side = 128;
  o.width = 0.125;
  o.epochs = 3;
  o.warmup_steps = 40;
  o.write_videos = false;
  o.write_point_cloud = false;
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
  // Measured on this configuration (2-core VM): AbsRel 0.183 -> 0.149 (-19%), geometric loss
  // 1.280 -> 1.249 (-2.4%; three short epochs). Margins: at least 10% lower AbsRel and 1% lower
  // loss; an untrained network stays at the initial values and a diverging one goes above them.
  EXPECT_LT(abs_rel1, 0.90 * abs_rel0) << "initial " << abs_rel0 << " final " << abs_rel1;
  EXPECT_LT(r.final_loss, 0.99 * r.initial_loss)
      << "initial " << r.initial_loss << " final " << r.final_loss;
  ASSERT_EQ(r.epoch_losses.size(), 3u);
  for (double l : r.epoch_losses) EXPECT_TRUE(std::isfinite(l));
}

}  // namespace
}  // namespace cvd
