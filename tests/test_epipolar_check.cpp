// The epipolar distance of a flow from two cameras (pipeline/geometry/epipolar_distance.h): zero
// for the exact flow of the generated scene, large when one camera is turned, the rotation's
// homography where the centres coincide; and which pairs the check drops.
#include <gtest/gtest.h>

#include <cmath>

#include "engine/error.h"
#include "exact_scene_flow.h"
#include "pipeline/geometry/epipolar_distance.h"
#include "pipeline/run/pair_camera_check.h"
#include "pipeline/run/run_options.h"
#include "scene/synthetic_scene.h"

namespace cvd {
namespace {

NamedCamera camera(const SyntheticScene& s, size_t k) {
  NamedCamera c;
  c.pose = s.frames[k].pose;
  c.intrinsics = s.intrinsics;
  return c;
}

Eigen::Matrix3d turn(double deg, const Eigen::Vector3d& axis) {
  return Eigen::AngleAxisd(deg * M_PI / 180.0, axis.normalized()).toRotationMatrix();
}

SyntheticScene small_scene() {
  SyntheticSceneOptions so;
  so.frames = 6;
  so.width = 192;
  so.height = 128;
  so.supersampling = 1;
  return render_synthetic_scene(so);
}

TEST(EpipolarDistance, ExactFlowLiesOnTheEpipolarLinesAndATurnedCameraDoesNot) {
  const SyntheticScene s = small_scene();
  cv::Mat flow, mask;
  test::exact_scene_flow(s, 0, 4, flow, mask);
  ASSERT_GT(cv::countNonZero(mask), flow.total() / 2);
  const NamedCamera a = camera(s, 0), b = camera(s, 4);
  const double exact = median_epipolar_distance(flow, mask, a, b);
  EXPECT_GE(exact, 0.0);
  EXPECT_LT(exact, 1e-3);
  // Camera b turned by one degree (a pose glitch). The scene's camera moves sideways, so the
  // epipolar lines run about horizontally: a turn about the horizontal axis moves points across
  // them (at this focal, ~100-200 px, a degree is 2-3 px), one about the vertical axis mostly
  // along them, which no depth-free test can see.
  auto turned = [&](const Eigen::Vector3d& axis) {
    NamedCamera c = b;
    c.pose.R = b.pose.R * turn(1.0, axis);
    return median_epipolar_distance(flow, mask, a, c);
  };
  const double across = turned(Eigen::Vector3d::UnitX()), along = turned(Eigen::Vector3d::UnitY());
  EXPECT_GT(across, 0.5);
  EXPECT_GT(along, 20 * exact);
  EXPECT_LT(along, across / 3);
  // The distance does not depend on the baseline's length, only on its direction.
  NamedCamera far = b;
  far.pose.t = a.pose.t + 7.0 * (b.pose.t - a.pose.t);
  EXPECT_LT(median_epipolar_distance(flow, mask, a, far), 1e-3);
}

TEST(EpipolarDistance, OnlyTheMaskedPixelsCount) {
  const SyntheticScene s = small_scene();
  cv::Mat flow, mask;
  test::exact_scene_flow(s, 1, 2, flow, mask);
  // Garbage where the mask is zero: ignored. Without the mask the garbage is most of the image.
  cv::Mat bad = flow.clone();
  for (int y = 0; y < bad.rows; ++y)
    for (int x = 0; x < bad.cols; ++x)
      if (!mask.at<uint8_t>(y, x) || x < bad.cols * 3 / 4) bad.at<cv::Vec2f>(y, x) = {30.f, -20.f};
  cv::Mat keep = mask.clone();
  keep.colRange(0, bad.cols * 3 / 4).setTo(0);
  ASSERT_GT(cv::countNonZero(keep), 100);
  EXPECT_LT(median_epipolar_distance(bad, keep, camera(s, 1), camera(s, 2)), 1e-3);
  EXPECT_GT(median_epipolar_distance(bad, cv::Mat(), camera(s, 1), camera(s, 2)), 1.0);
  // Nothing sampled: negative.
  EXPECT_LT(
      median_epipolar_distance(bad, cv::Mat::zeros(bad.size(), CV_8U), camera(s, 1), camera(s, 2)),
      0.0);
}

TEST(EpipolarDistance, WithoutABaselineTheRotationsHomographyIsTheMeasure) {
  NamedCamera a, b;
  a.intrinsics = b.intrinsics = {150, 150, 96, 64, 192, 128};
  a.pose.t = b.pose.t = Eigen::Vector3d(0.3, -0.2, 1.0);
  a.pose.R = turn(10, {0.2, 1, 0.1});
  b.pose.R = a.pose.R * turn(3, {1, 0.5, 0});
  const Eigen::Matrix3d H =
      b.intrinsics.K() * (b.pose.R.transpose() * a.pose.R) * a.intrinsics.K().inverse();
  cv::Mat flow(128, 192, CV_32FC2);
  for (int y = 0; y < flow.rows; ++y)
    for (int x = 0; x < flow.cols; ++x) {
      const Eigen::Vector3d h = H * Eigen::Vector3d(x, y, 1);
      flow.at<cv::Vec2f>(y, x) = cv::Vec2f(float(h.x() / h.z() - x), float(h.y() / h.z() - y));
    }
  EXPECT_LT(median_epipolar_distance(flow, cv::Mat(), a, b), 1e-3);
  NamedCamera off = b;
  off.pose.R = b.pose.R * turn(1, {0, 1, 0});
  // One degree at 150 px focal: 2.6 px at the image centre, more towards its sides.
  const double d = median_epipolar_distance(flow, cv::Mat(), a, off);
  EXPECT_GT(d, 2.4);
  EXPECT_LT(d, 4.0);
}

TEST(EpipolarCheck, DropsOutliersAboveBothTheMedianFactorAndTheFloor) {
  std::vector<double> d(20, 0.1);
  d.push_back(2.0);
  d.push_back(0.5);   // 5x the median, under the floor (0.004 * 192 = 0.768 px)
  d.push_back(0.9);   // above both
  d.push_back(-1.0);  // unknown: never dropped, not in the median
  const EpipolarCheck c = check_epipolar_distances(d, 192);
  EXPECT_DOUBLE_EQ(c.median_px, 0.1);
  EXPECT_NEAR(c.threshold_px, 0.768, 1e-12);
  ASSERT_EQ(c.drop.size(), d.size());
  for (size_t k = 0; k < d.size(); ++k) EXPECT_EQ(c.drop[k], k == 20 || k == 22) << k;
  EXPECT_EQ(c.capped, 0);
  // Where the median is high, the factor decides: 3 x 0.4 = 1.2 px.
  std::vector<double> e(10, 0.4);
  e[3] = 1.1;
  e[7] = 1.3;
  const EpipolarCheck f = check_epipolar_distances(e, 192);
  EXPECT_NEAR(f.threshold_px, 1.2, 1e-12);
  for (size_t k = 0; k < e.size(); ++k) EXPECT_EQ(f.drop[k], k == 7) << k;
}

TEST(EpipolarCheck, DropsAtMostAQuarterOfThePairsTheWorstFirst) {
  std::vector<double> d = {0.1, 5.0, 0.1, 3.0, 0.1, 4.0, 0.1, 2.0, 0.1, 6.0};
  const EpipolarCheck c = check_epipolar_distances(d, 192);
  // Median 1.05 -> threshold 3.15: 4, 5, 6 px are above it; the cap (2 of 10) keeps 4 px.
  int dropped = 0;
  for (bool b : c.drop) dropped += b;
  EXPECT_EQ(dropped, 2);
  EXPECT_TRUE(c.drop[9]);
  EXPECT_TRUE(c.drop[1]);
  EXPECT_FALSE(c.drop[5]);
  EXPECT_EQ(c.capped, 1);
  EXPECT_TRUE(check_epipolar_distances({}, 192).drop.empty());
}

// One pass measures a clip's pairs against several camera sets (--given-poses auto compares the
// given and the adjusted cameras, then the pairs' check reuses the chosen set's distances): the
// same numbers as measuring each set alone, and the same check as measuring again.
TEST(PairCameraCheck, OnePassOverSeveralCameraSetsMeasuresEachAsAlone) {
  const SyntheticScene s = small_scene();
  FlowStage flow;
  flow.half_precision = false;
  for (const FramePair p :
       {FramePair{0, 1}, FramePair{0, 2}, FramePair{1, 4}, FramePair{3, 4}, FramePair{2, 5}}) {
    FlowPairData d;
    d.pair = p;
    test::exact_scene_flow(s, size_t(p.first), size_t(p.second), d.forward, d.forward_mask);
    d.backward = d.forward.clone();
    d.backward_mask = d.forward_mask.clone();
    d.kept = true;
    flow.pairs.push_back(d);
  }
  std::vector<NamedCamera> exact, glitch;
  for (size_t k = 0; k < s.frames.size(); ++k) exact.push_back(camera(s, k));
  glitch = exact;
  glitch[4].pose.R = exact[4].pose.R * turn(1.0, Eigen::Vector3d::UnitX());  // pairs with 4 fail
  const std::vector<PairDistances> m = measure_pairs_against_cameras(flow, {exact, glitch});
  ASSERT_EQ(m.size(), 2u);
  for (size_t set = 0; set < 2; ++set) {
    const std::vector<NamedCamera>& cams = set == 0 ? exact : glitch;
    ASSERT_EQ(m[set].px.size(), flow.pairs.size());
    EXPECT_EQ(m[set].long_side, 192);
    for (size_t k = 0; k < flow.pairs.size(); ++k) {
      const FlowPairData& d = flow.pairs[k];
      EXPECT_EQ(m[set].px[k],
                median_epipolar_distance(d.forward, d.forward_mask, cams[size_t(d.pair.first)],
                                         cams[size_t(d.pair.second)]))
          << set << " " << k;
    }
  }
  EXPECT_GT(m[1].px[2], 0.5);
  EXPECT_LT(m[1].px[0], 1e-3);
  RunOptions o;
  o.epipolar_check = "drop";
  const std::vector<std::string> names = {"a", "b", "c", "d", "e", "f"};
  FlowStage measured_again = flow, handed_on = flow;
  const nlohmann::json again = check_pairs_against_cameras(o, measured_again, glitch, names);
  const nlohmann::json reused = check_pairs_against_cameras(o, handed_on, glitch, names, &m[1]);
  EXPECT_EQ(again.dump(), reused.dump());
  // Both pairs with frame 4 contradict it; the quarter's cap drops only the worse (3 -> 4).
  EXPECT_EQ(again.at("dropped"), 1);
  EXPECT_EQ(again.at("above_threshold_not_named"), 1);
  ASSERT_EQ(handed_on.pairs.size(), measured_again.pairs.size());
  for (size_t k = 0; k < handed_on.pairs.size(); ++k)
    EXPECT_EQ(handed_on.pairs[k].pair, measured_again.pairs[k].pair);
  PairDistances short_measure = m[1];
  short_measure.px.pop_back();
  FlowStage unchecked = flow;
  EXPECT_THROW(check_pairs_against_cameras(o, unchecked, glitch, names, &short_measure), Error);
}

}  // namespace
}  // namespace cvd
