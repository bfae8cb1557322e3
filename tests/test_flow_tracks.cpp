// Flow tracks (pipeline/geometry/flow_tracks.h) on the generated scene with exact flow from its
// depth and poses: every kept point lies on the true surface, points reach most frames, and a
// track never outlives an untrusted pixel.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "exact_scene_flow.h"
#include "pipeline/geometry/flow_tracks.h"
#include "scene/synthetic_scene.h"

namespace cvd {
namespace {

constexpr int kSlowClipFrames = 400;

// A generated clip with its exact cameras and exact consecutive flows.
struct ExactFlowClip {
  SyntheticScene scene;
  std::vector<NamedCamera> cams;
  std::vector<cv::Mat> flows, masks;
};

ExactFlowClip exact_flow_clip(const SyntheticSceneOptions& so) {
  ExactFlowClip c{render_synthetic_scene(so), {}, {}, {}};
  const size_t n = c.scene.frames.size();
  c.cams.resize(n);
  c.flows.resize(n);
  c.masks.resize(n);
  for (size_t k = 0; k < n; ++k) {
    c.cams[k].pose = c.scene.frames[k].pose;
    c.cams[k].intrinsics = c.scene.intrinsics;
    if (k + 1 < n) test::exact_scene_flow(c.scene, k, k + 1, c.flows[k], c.masks[k]);
  }
  return c;
}

// |depth of each point / true depth - 1| at the pixel it projects to (rounded), every frame,
// sorted; a point projecting outside the image fails the test.
std::vector<double> sorted_depth_errors(const ExactFlowClip& c,
                                        const std::vector<std::vector<Eigen::Vector3d>>& points) {
  std::vector<double> errors;
  const Intrinsics& K = c.scene.intrinsics;
  for (size_t k = 0; k < points.size(); ++k) {
    const cv::Mat& depth = c.scene.frames[k].depth;
    for (const Eigen::Vector3d& X : points[k]) {
      const Eigen::Vector3d p = c.cams[k].pose.R.transpose() * (X - c.cams[k].pose.t);
      const int u = int(std::lround(K.fx * p.x() / p.z() + K.cx));
      const int v = int(std::lround(K.fy * p.y() / p.z() + K.cy));
      EXPECT_TRUE(u >= 0 && v >= 0 && u < depth.cols && v < depth.rows) << u << ", " << v;
      if (u < 0 || v < 0 || u >= depth.cols || v >= depth.rows) continue;
      errors.push_back(std::abs(p.z() / depth.at<float>(v, u) - 1.0));
    }
  }
  std::sort(errors.begin(), errors.end());
  return errors;
}

TEST(FlowTracks, PointsFromExactFlowLieOnTheSurfaceAndReachMostFrames) {
  SyntheticSceneOptions so;
  so.frames = 16;
  so.width = 128;
  so.height = 80;
  so.supersampling = 1;
  const ExactFlowClip c = exact_flow_clip(so);
  const size_t n = c.cams.size();
  std::vector<std::vector<Eigen::Vector3d>> points(n);
  FlowTrackOptions o;
  o.min_parallax_deg = 0.5;  // the generated clip moves little between frames
  const FlowTrackStats st = triangulate_flow_tracks(c.cams, c.flows, c.masks, points, o);
  ASSERT_GT(st.kept, 50) << st.tracks << " tracks";
  size_t frames_with_points = 0;
  for (size_t k = 0; k < n; ++k)
    if (points[k].size() >= 8) ++frames_with_points;
  EXPECT_GE(frames_with_points, n - 1);
  // Compared at the rounded pixel: exact on surfaces, off only where that pixel crosses an edge.
  const std::vector<double> errors = sorted_depth_errors(c, points);
  ASSERT_FALSE(errors.empty());
  EXPECT_LT(errors[errors.size() / 2], 0.005);
  EXPECT_LT(errors[errors.size() * 95 / 100], 0.03);
}

// A slow clip (the generated path over many frames, like a long recording): 16-frame tracks see
// too little parallax to keep a point per frame; the lengthening tries longer tracks, and their
// points still lie on the surface.
TEST(FlowTracks, SlowClipGetsPointsFromLongerTracks) {
  SyntheticSceneOptions so;
  so.frames = kSlowClipFrames;
  so.width = 64;
  so.height = 40;
  so.supersampling = 1;
  so.moving_object = false;
  const ExactFlowClip c = exact_flow_clip(so);
  const size_t n = c.cams.size();
  const FlowTrackOptions o;  // the run's defaults: 16 frames, 1.5 degrees
  std::vector<std::vector<Eigen::Vector3d>> short_points(n), points(n);
  const FlowTrackStats short_tracks =
      triangulate_flow_tracks(c.cams, c.flows, c.masks, short_points, o);
  ASSERT_LT(short_tracks.kept, static_cast<int>(n)) << "the clip is not slow enough";
  const FlowTrackStats st =
      triangulate_flow_tracks_lengthening(c.cams, c.flows, c.masks, points, static_cast<int>(n), o);
  EXPECT_GE(st.kept, static_cast<int>(n))
      << short_tracks.kept << " kept with 16 frames, " << st.kept << " with " << st.max_length;
  EXPECT_GT(st.max_length, o.max_length);
  const std::vector<double> errors = sorted_depth_errors(c, points);
  ASSERT_FALSE(errors.empty());
  EXPECT_LT(errors[errors.size() / 2], 0.01);
  // Nothing more asked for: the given length's result stands.
  std::vector<std::vector<Eigen::Vector3d>> again(n);
  EXPECT_EQ(triangulate_flow_tracks_lengthening(c.cams, c.flows, c.masks, again, 0, o).max_length,
            o.max_length);
}

TEST(FlowTracks, AnUntrustedPixelEndsTheTrackAndNoFlowNoPoints) {
  const size_t n = 4;
  std::vector<NamedCamera> cams(n);
  for (size_t k = 0; k < n; ++k) {
    cams[k].intrinsics = {50, 50, 16, 16, 32, 32};
    cams[k].pose.t = Eigen::Vector3d(0.2 * double(k), 0, 0);
  }
  // A fronto-parallel plane at depth 2: x moves by -f * 0.2 / 2 = -5 px per frame.
  std::vector<cv::Mat> flows(n), masks(n);
  for (size_t k = 0; k + 1 < n; ++k) {
    flows[k] = cv::Mat(32, 32, CV_32FC2, cv::Scalar(-5.f, 0.f));
    masks[k] = cv::Mat(32, 32, CV_8U, cv::Scalar(255));
  }
  std::vector<std::vector<Eigen::Vector3d>> points(n);
  FlowTrackOptions o;
  o.start_every = 1;
  const FlowTrackStats all = triangulate_flow_tracks(cams, flows, masks, points, o);
  ASSERT_GT(all.kept, 0);
  for (const auto& frame : points)
    for (const Eigen::Vector3d& X : frame) EXPECT_NEAR(X.z(), 2.0, 1e-6);
  // Untrusted second flow: no track reaches 3 views.
  masks[1].setTo(0);
  std::vector<std::vector<Eigen::Vector3d>> none(n);
  EXPECT_EQ(triangulate_flow_tracks(cams, flows, masks, none, o).kept, 0);
  // A missing flow is the same.
  std::vector<cv::Mat> no_flows(n), no_masks(n);
  EXPECT_EQ(triangulate_flow_tracks(cams, no_flows, no_masks, none, o).tracks, 0);
}

}  // namespace
}  // namespace cvd
