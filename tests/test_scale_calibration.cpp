// Pose stage building blocks besides the files: the paper's pair sampling, the calibration of the
// poses' scale to network depth, and the parallax of COLMAP's points. (Pose files:
// test_poses.cpp.)
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <opencv2/imgproc.hpp>
#include <random>
#include <set>

#include "engine/error.h"
#include "pipeline/flow/pair_sampling.h"
#include "pipeline/geometry/scale_calibration.h"
#include "pipeline/io/trajectory_io.h"
#include "pipeline/poses/colmap_point_parallax.h"
#include "test_support.h"

namespace cvd {
namespace {

namespace fs = std::filesystem;

// ---- Pair sampling ------------------------------------------------------------------------------

// The paper's definition, evaluated pair by pair (independently of the generator's loops).
bool in_hierarchy(int i, int j, int n) {
  if (n < 2 || j <= i) return false;
  int max_level = int(std::floor(std::log2(double(n - 1)) + 1e-12));
  for (int l = 0; l <= max_level; ++l) {
    long dist = std::lround(std::pow(2.0, l));
    if (j - i != dist) continue;
    if (l == 0) return true;
    long mod = std::lround(std::pow(2.0, l - 1));
    if (i % mod == 0) return true;
  }
  return false;
}

TEST(PairSampling, MatchesThePaperDefinition) {
  for (int n : {1, 2, 3, 8, 9, 65, 150}) {
    SCOPED_TRACE("N = " + std::to_string(n));
    std::set<std::pair<int, int>> expected;
    for (int i = 0; i < n; ++i)
      for (int j = i + 1; j < n; ++j)
        if (in_hierarchy(i, j, n)) expected.insert({i, j});
    auto pairs = hierarchical_pairs(n);
    std::set<std::pair<int, int>> got;
    for (const auto& p : pairs) {
      EXPECT_LT(p.first, p.second);
      EXPECT_GE(p.first, 0);
      EXPECT_LT(p.second, n);
      got.insert({p.first, p.second});
    }
    EXPECT_EQ(got.size(), pairs.size()) << "duplicate pairs";
    EXPECT_EQ(got, expected);
  }
  // Counts by hand: N=3: |S0|=2, |S1|=1.  N=8: 7 + 6 + 2 (pairs (0,4), (2,6)).
  // N=9: 8 + 7 + 3 ((0,4),(2,6),(4,8)) + 1 ((0,8)).
  EXPECT_EQ(hierarchical_pairs(1).size(), 0u);
  EXPECT_EQ(hierarchical_pairs(2).size(), 1u);
  EXPECT_EQ(hierarchical_pairs(3).size(), 3u);
  EXPECT_EQ(hierarchical_pairs(8).size(), 15u);
  EXPECT_EQ(hierarchical_pairs(9).size(), 19u);
  EXPECT_EQ(hierarchical_pairs(0).size(), 0u);
  EXPECT_THROW(hierarchical_pairs(-1), Error);
}

// ---- Scale calibration --------------------------------------------------------------------------

// Synthetic scene: the plane Z = 4 (world), seen by cameras near the origin looking along +Z.
struct PlaneScene {
  Intrinsics k{100, 100, 40, 30, 80, 60};
  double plane_z = 4.0;
  std::vector<NamedCamera> cameras;

  explicit PlaneScene(int n) {
    for (int i = 0; i < n; ++i) {
      NamedCamera c;
      c.name = "f" + std::to_string(i);
      c.intrinsics = k;
      c.pose.R = Eigen::AngleAxisd(0.03 * i, Eigen::Vector3d::UnitY()).toRotationMatrix() *
                 Eigen::AngleAxisd(-0.02 * i, Eigen::Vector3d::UnitX()).toRotationMatrix();
      c.pose.t = Eigen::Vector3d(0.1 * i, -0.05 * i, 0.08 * i);
      cameras.push_back(c);
    }
  }
  // Depth (camera z) of the plane seen through pixel (u, v) of camera c.
  double depth(const NamedCamera& c, double u, double v) const {
    Eigen::Vector3d ray((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0);  // z = 1 in camera
    Eigen::Vector3d dir = c.pose.R * ray;
    return (plane_z - c.pose.t.z()) / dir.z();
  }
  Eigen::Vector3d backproject(const NamedCamera& c, double u, double v, double z) const {
    return c.pose.transform(Eigen::Vector3d((u - k.cx) / k.fx * z, (v - k.cy) / k.fy * z, z));
  }
  // The "network" depth map: scale * true depth, with multiplicative noise and holes.
  cv::Mat network_depth(const NamedCamera& c, double scale, double noise, std::mt19937& rng) const {
    std::normal_distribution<double> n(0.0, noise);
    std::uniform_real_distribution<double> u01(0, 1);
    cv::Mat d(k.height, k.width, CV_32F);
    for (int y = 0; y < k.height; ++y)
      for (int x = 0; x < k.width; ++x)
        d.at<float>(y, x) = u01(rng) < 0.05 ? 0.f : float(scale * depth(c, x, y) * (1.0 + n(rng)));
    return d;
  }
};

TEST(ScaleCalibration, RecoversAKnownScaleDespiteNoiseAndOutliers) {
  const double true_scale = 2.5;  // network units per SfM unit
  PlaneScene scene(6);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> px(2, 77), py(2, 57), u01(0, 1);
  std::normal_distribution<double> off(0.0, 1.5);
  std::vector<cv::Mat> depths;
  std::vector<std::vector<Eigen::Vector3d>> points(scene.cameras.size());
  for (size_t i = 0; i < scene.cameras.size(); ++i) {
    const auto& c = scene.cameras[i];
    depths.push_back(scene.network_depth(c, true_scale, 0.03, rng));
    int count = i == 4 ? 5 : 200;  // frame 4: too few points -> invalid
    for (int p = 0; p < count; ++p) {
      double u = px(rng), v = py(rng);
      Eigen::Vector3d x = scene.backproject(c, u, v, scene.depth(c, u, v));
      if (u01(rng) < 0.25) x += Eigen::Vector3d(off(rng), off(rng), off(rng));  // 25% outliers
      points[i].push_back(x);
    }
    // Points behind the camera and outside the image must be ignored.
    points[i].push_back(c.pose.transform(Eigen::Vector3d(0, 0, -2)));
    points[i].push_back(c.pose.transform(Eigen::Vector3d(50, 0, 1)));
  }
  scene.cameras[5].registered = false;  // an unregistered frame is invalid too
  ScaleCalibrationOptions opt;
  opt.min_points = 20;
  ScaleCalibrationResult r = calibrate_scale(scene.cameras, depths, points, opt);
  ASSERT_EQ(r.frame_scales.size(), 6u);
  EXPECT_EQ(r.num_valid(), 4);
  EXPECT_FALSE(r.frame_valid[4]);
  EXPECT_FALSE(r.frame_valid[5]);
  EXPECT_TRUE(std::isnan(r.frame_scales[4]));
  EXPECT_LE(r.frame_sample_counts[4], 5);
  // Tolerance: 3% per-pixel noise and 25% outliers; the median of ~190 samples is within ~1%.
  for (int i = 0; i < 4; ++i) {
    EXPECT_TRUE(r.frame_valid[i]);
    EXPECT_NEAR(r.frame_scales[i], true_scale, 0.03 * true_scale) << "frame " << i;
    EXPECT_GE(r.frame_sample_counts[i], 150);
    EXPECT_LE(r.frame_sample_counts[i], 200);
  }
  EXPECT_NEAR(r.scale, true_scale, 0.015 * true_scale);
  // Invalid frames keep a (scaled) pose in the output.
  ASSERT_EQ(r.cameras.size(), 6u);
  for (size_t i = 0; i < 6; ++i) {
    EXPECT_LT((r.cameras[i].pose.t - r.scale * scene.cameras[i].pose.t).norm(), 1e-12);
    EXPECT_EQ(r.cameras[i].pose.R, scene.cameras[i].pose.R);
    EXPECT_EQ(r.cameras[i].name, scene.cameras[i].name);
  }
}

TEST(ScaleCalibration, ScaledPosesAgreeWithNetworkDepth) {
  // Noise-free: after calibration, a pixel of frame 0 back-projected with its network depth and
  // the scaled pose lands where the scene puts it in frame 3, with the network depth of frame 3.
  const double true_scale = 0.4;
  PlaneScene scene(4);
  std::mt19937 rng(6);
  std::vector<cv::Mat> depths;
  std::vector<std::vector<Eigen::Vector3d>> points(4);
  for (size_t i = 0; i < 4; ++i) {
    depths.push_back(scene.network_depth(scene.cameras[i], true_scale, 0.0, rng));
    for (int y = 5; y < 55; y += 5)
      for (int x = 5; x < 75; x += 5)
        points[i].push_back(
            scene.backproject(scene.cameras[i], x, y, scene.depth(scene.cameras[i], x, y)));
  }
  ScaleCalibrationResult r = calibrate_scale(scene.cameras, depths, points);
  // Tolerance: bilinear sampling of a plane's depth (not linear in pixels) over 5% holes.
  EXPECT_NEAR(r.scale, true_scale, 1e-3 * true_scale);
  const NamedCamera& a = r.cameras[0];
  const NamedCamera& b = r.cameras[3];
  for (auto [u, v] : {std::pair{20.0, 15.0}, {40.0, 30.0}, {55.0, 40.0}}) {
    double za = true_scale * scene.depth(scene.cameras[0], u, v);  // network depth at (u, v)
    Eigen::Vector3d xw = scene.backproject(a, u, v, za);           // network units
    Eigen::Vector3d xb = b.pose.inverse().transform(xw);
    double ub = scene.k.fx * xb.x() / xb.z() + scene.k.cx;
    double vb = scene.k.fy * xb.y() / xb.z() + scene.k.cy;
    // Ground truth: the same scene point through the unscaled (SfM) cameras.
    Eigen::Vector3d xw_sfm = scene.backproject(scene.cameras[0], u, v, za / true_scale);
    Eigen::Vector3d xb_sfm = scene.cameras[3].pose.inverse().transform(xw_sfm);
    EXPECT_NEAR(ub, scene.k.fx * xb_sfm.x() / xb_sfm.z() + scene.k.cx, 0.05);
    EXPECT_NEAR(vb, scene.k.fy * xb_sfm.y() / xb_sfm.z() + scene.k.cy, 0.05);
    EXPECT_NEAR(xb.z(), true_scale * scene.depth(scene.cameras[3], ub, vb), 1e-3 * xb.z());
  }
}

TEST(ScaleCalibration, UsesColmapPointsByNameAndRescalesIntrinsics) {
  // Depth maps at half the intrinsics' resolution; points come from a model keyed by name, with
  // the model's images in a different order than the frames.
  const double true_scale = 3.0;
  PlaneScene scene(3);
  std::mt19937 rng(7);
  ColmapModel model;
  int64_t next_point = 0;
  std::vector<cv::Mat> depths;
  for (int i = 2; i >= 0; --i) {
    ColmapImage img;
    img.id = i + 1;
    img.name = scene.cameras[i].name;
    img.pose = scene.cameras[i].pose;
    for (int y = 4; y < 56; y += 4)
      for (int x = 4; x < 76; x += 4) {
        ColmapPoint p;
        p.id = next_point++;
        p.xyz = scene.backproject(scene.cameras[i], x, y, scene.depth(scene.cameras[i], x, y));
        model.points[p.id] = p;
        img.observations.push_back({{double(x), double(y)}, p.id});
      }
    model.images[img.name] = img;
  }
  for (int i = 0; i < 3; ++i) {
    cv::Mat full = scene.network_depth(scene.cameras[i], true_scale, 0.0, rng);
    cv::Mat half;
    cv::resize(full, half, {40, 30}, 0, 0, cv::INTER_NEAREST);
    depths.push_back(half);
  }
  ScaleCalibrationResult r = calibrate_scale(scene.cameras, depths, model);
  EXPECT_EQ(r.num_valid(), 3);
  // Tolerance: nearest-neighbour downsampling shifts samples by up to a pixel on a tilted plane.
  EXPECT_NEAR(r.scale, true_scale, 0.02 * true_scale);
  // No points for any frame -> a clear numerical error.
  try {
    calibrate_scale(scene.cameras, depths, ColmapModel{});
    ADD_FAILURE() << "no error without points";
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), ErrorCategory::numerical);
  }
  EXPECT_THROW(calibrate_scale(scene.cameras, {depths[0]}, model), Error);
}

// A run on every 2nd frame from frame 1 writes each frame's time in the input as its poses.txt
// timestamp (frame 1 + 2k of an image folder, read at 30 fps: (1 + 2k) / 30 s, the generated
// scene's own timestamps; it wrote k / fps before), and that
// poses.txt, one pose per selected frame, is taken back by a run with the same frame selection
// (matched in order) with the same poses out.

TEST(ColmapPointParallax, WidestAngleBetweenTheObservingCameras) {
  ColmapModel m;
  const auto image = [&](int id, double x) {
    ColmapImage im;
    im.id = id;
    im.name = "f" + std::to_string(id);
    im.camera_id = 1;
    im.pose.t = Eigen::Vector3d(x, 0, 0);
    m.images[im.name] = im;
  };
  image(1, 0.0);
  image(2, 1.0);
  image(3, 0.5);
  ColmapPoint a;
  a.id = 1;
  a.xyz = Eigen::Vector3d(0.5, 0, 2);
  a.track = {{1, 0}, {3, 0}, {2, 0}};
  ColmapPoint b;
  b.id = 2;
  b.xyz = Eigen::Vector3d(0, 0, 5);
  b.track = {{1, 1}, {9, 0}};
  m.points[a.id] = a;
  m.points[b.id] = b;
  const std::vector<double> p = colmap_point_parallax_deg(m);
  ASSERT_EQ(p.size(), 1u);
  EXPECT_NEAR(p[0], 2.0 * std::atan(0.25) * 180.0 / M_PI, 1e-9);
}

}  // namespace
}  // namespace cvd
