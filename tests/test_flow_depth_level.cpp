// The flat start's depth level when no sparse point could be triangulated
// (pipeline/geometry/flow_depth_level.h): exact flow of a plane seen by two cameras with a small
// baseline, with and without noise, in two units, without translation, and from cameras the
// flow contradicts.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>

#include "pipeline/geometry/flow_depth_level.h"

namespace cvd {
namespace {

constexpr int kW = 160, kH = 120;
constexpr double kPlaneDepth = 2.5;  // a fronto-parallel plane in front of camera 0

Intrinsics intrinsics() { return {130.0, 130.0, 80.0, 60.0, kW, kH}; }

NamedCamera camera(const Eigen::Vector3d& centre, const Eigen::Vector3d& axis_angle) {
  NamedCamera c;
  c.intrinsics = intrinsics();
  const double angle = axis_angle.norm();
  if (angle > 0) c.pose.R = Eigen::AngleAxisd(angle, axis_angle / angle).toRotationMatrix();
  c.pose.t = centre;
  return c;
}

// The flow from camera a to camera b of the plane z = kPlaneDepth in a's frame (a at the
// origin, unrotated), with Gaussian noise of `sigma_px`; every pixel trusted.
void plane_flow(const NamedCamera& a, const NamedCamera& b, double sigma_px, cv::Mat& flow,
                cv::Mat& mask, uint32_t seed = 1) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, sigma_px);
  const Intrinsics& K = a.intrinsics;
  flow.create(kH, kW, CV_32FC2);
  mask = cv::Mat(kH, kW, CV_8U, cv::Scalar(255));
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const Eigen::Vector3d X = a.pose.transform(
          kPlaneDepth * Eigen::Vector3d((x - K.cx) / K.fx, (y - K.cy) / K.fy, 1.0));
      const Eigen::Vector3d p = b.pose.R.transpose() * (X - b.pose.t);
      const double u = K.fx * p.x() / p.z() + K.cx, v = K.fy * p.y() / p.z() + K.cy;
      flow.at<cv::Vec2f>(y, x) = cv::Vec2f(float(u - x + noise(rng)), float(v - y + noise(rng)));
    }
}

struct Pair {
  std::vector<NamedCamera> cams;
  cv::Mat flow, mask;
};

// Cameras 1 cm apart (0.3 px of parallax per pixel at the plane: below the triangulation's 1
// degree), the second turned by 2 degrees; the positions scaled by `unit`.
Pair small_baseline_pair(double sigma_px, double unit = 1.0) {
  Pair p;
  p.cams = {camera(Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()),
            camera(Eigen::Vector3d(0.006, 0.003, 0.002), Eigen::Vector3d(0.0, 0.035, 0.01))};
  plane_flow(p.cams[0], p.cams[1], sigma_px, p.flow, p.mask);
  for (NamedCamera& c : p.cams) c.pose.t *= unit;
  return p;
}

FlowDepthLevel level_of(const Pair& p) {
  InverseDepthSamples s;
  add_inverse_depth_samples(p.cams[0], p.cams[1], p.flow, p.mask, s);
  return flow_depth_level(s, p.cams);
}

TEST(FlowDepthLevel, ExactFlowGivesThePlaneDepth) {
  const FlowDepthLevel l = level_of(small_baseline_pair(0.0));
  EXPECT_EQ(l.source, "flow");
  EXPECT_EQ(l.samples, size_t(kW / 4 * kH / 4));
  // f32 flow: the projections are rounded to ~1e-5 px against ~0.3 px of parallax.
  EXPECT_NEAR(l.depth, kPlaneDepth, 1e-3 * kPlaneDepth);
}

TEST(FlowDepthLevel, NoisyFlowStaysNearThePlaneDepth) {
  // Noise of 0.1 px (DIS on a good pair) against 0.2-0.3 px of parallax: each sample's inverse
  // depth is off by up to ~50%, the weighted median by a few percent.
  const FlowDepthLevel l = level_of(small_baseline_pair(0.1));
  EXPECT_EQ(l.source, "flow");
  RecordProperty("depth", std::to_string(l.depth));
  EXPECT_NEAR(l.depth, kPlaneDepth, 0.05 * kPlaneDepth);  // measured 2.484 (-0.6%)
}

TEST(FlowDepthLevel, TheLevelIsInTheUnitsOfThePoses) {
  for (double unit : {1e-3, 1e3}) {
    const FlowDepthLevel a = level_of(small_baseline_pair(0.1)),
                         b = level_of(small_baseline_pair(0.1, unit));
    EXPECT_NEAR(b.depth, unit * a.depth, 1e-9 * unit * a.depth) << "unit " << unit;
  }
}

TEST(FlowDepthLevel, PureRotationHasNoSampleAndKeepsDepthOne) {
  Pair p;
  p.cams = {camera(Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()),
            camera(Eigen::Vector3d::Zero(), Eigen::Vector3d(0.0, 0.035, 0.01))};
  plane_flow(p.cams[0], p.cams[1], 0.1, p.flow, p.mask);
  const FlowDepthLevel l = level_of(p);
  EXPECT_EQ(l.samples, 0u);
  EXPECT_EQ(l.source, "none");
  EXPECT_EQ(l.depth, 1.0);
}

TEST(FlowDepthLevel, CamerasTheFlowContradictsFallBackToTheBaseline) {
  // The second camera's centre mirrored: every pixel's inverse depth comes out negative.
  Pair p = small_baseline_pair(0.0);
  p.cams[1].pose.t = -p.cams[1].pose.t;
  const FlowDepthLevel l = level_of(p);
  EXPECT_LT(l.median_inverse_depth, 0.0);
  EXPECT_EQ(l.source, "baseline");
  const double baseline = p.cams[1].pose.t.norm();
  EXPECT_NEAR(l.widest_baseline, baseline, 1e-12);
  EXPECT_NEAR(l.depth, baseline / std::tan(M_PI / 180.0), 1e-9);
}

TEST(FlowDepthLevel, UntrustedPixelsAndBadInputAreRejected) {
  Pair p = small_baseline_pair(0.0);
  p.mask.setTo(0);
  InverseDepthSamples s;
  add_inverse_depth_samples(p.cams[0], p.cams[1], p.flow, p.mask, s);
  EXPECT_TRUE(s.inverse_depth.empty());
  cv::Mat wrong(kH, kW, CV_32FC1, cv::Scalar(0));
  EXPECT_THROW(add_inverse_depth_samples(p.cams[0], p.cams[1], wrong, p.mask, s), std::exception);
  s.weight.push_back(1.0);
  EXPECT_THROW(flow_depth_level(s, p.cams), std::exception);
}

}  // namespace
}  // namespace cvd
