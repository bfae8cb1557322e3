// The built-in synthetic scene (scene/synthetic_scene.h), its files, and the PFM / image IO it
// shares with the pipeline.
#include <gtest/gtest.h>

#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>

#include "engine/error.h"
#include "pipeline/io/image_io.h"
#include "pipeline/io/pfm_io.h"
#include "scene/synthetic_scene.h"
#include "test_support.h"

namespace cvd {
namespace {

namespace fs = std::filesystem;

// 10 frames at the default size along the default path (frame k sits at t = k / 9).
const SyntheticScene& test_scene() {
  static const SyntheticScene scene = [] {
    SyntheticSceneOptions o;
    o.frames = 10;
    return render_synthetic_scene(o);
  }();
  return scene;
}

bool identical(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) return false;
  for (int y = 0; y < a.rows; ++y)
    if (std::memcmp(a.ptr(y), b.ptr(y), a.cols * a.elemSize()) != 0) return false;
  return true;
}

float bilinear(const cv::Mat& m, double x, double y, int channel = 0) {
  const int x0 = int(std::floor(x)), y0 = int(std::floor(y));
  const double fx = x - x0, fy = y - y0;
  const int c = m.channels();
  auto at = [&](int yy, int xx) {
    return m.depth() == CV_8U ? float(m.ptr<uchar>(yy)[xx * c + channel])
                              : m.ptr<float>(yy)[xx * c + channel];
  };
  return float((at(y0, x0) * (1 - fx) + at(y0, x0 + 1) * fx) * (1 - fy) +
               (at(y0 + 1, x0) * (1 - fx) + at(y0 + 1, x0 + 1) * fx) * fy);
}

struct Reprojection {
  size_t compared = 0;      // static pixels of frame i landing on static pixels of frame j
  size_t depth_agrees = 0;  // of which the GT depth of j matches within 1%
  double mean_abs_rgb = 0;  // over the agreeing pixels, per channel, 0..255
};

// Unprojects every static pixel of frame i with its GT depth and pose, projects it into frame j
// (with `pose_j`) and compares with frame j's GT. Inverse depth is interpolated bilinearly
// (exact on planes); pixels near the moving object in either frame are left out.
Reprojection reproject(const SyntheticScene& s, int i, int j, const Pose& pose_j) {
  const SyntheticFrame& a = s.frames[size_t(i)];
  const SyntheticFrame& b = s.frames[size_t(j)];
  const Intrinsics& K = s.intrinsics;
  cv::Mat moving_a, moving_b, inv_depth_b;
  const cv::Mat kernel = cv::Mat::ones(5, 5, CV_8U);
  cv::dilate(a.moving_mask, moving_a, kernel);
  cv::dilate(b.moving_mask, moving_b, kernel);
  cv::divide(1.0, b.depth, inv_depth_b, CV_32F);
  const Pose a_to_b = pose_j.inverse() * a.pose;
  Reprojection r;
  double rgb_sum = 0;
  for (int v = 0; v < K.height; ++v) {
    for (int u = 0; u < K.width; ++u) {
      if (moving_a.at<uchar>(v, u)) continue;
      const double d = a.depth.at<float>(v, u);
      const Eigen::Vector3d x_a(d * (u - K.cx) / K.fx, d * (v - K.cy) / K.fy, d);
      const Eigen::Vector3d x_b = a_to_b.transform(x_a);
      if (x_b.z() <= 0) continue;
      const double ub = K.fx * x_b.x() / x_b.z() + K.cx, vb = K.fy * x_b.y() / x_b.z() + K.cy;
      if (ub < 0 || vb < 0 || ub > K.width - 2 || vb > K.height - 2) continue;
      if (moving_b.at<uchar>(int(std::lround(vb)), int(std::lround(ub)))) continue;
      ++r.compared;
      const double z_b = 1.0 / bilinear(inv_depth_b, ub, vb);
      if (std::abs(z_b - x_b.z()) >= 0.01 * x_b.z()) continue;
      ++r.depth_agrees;
      for (int c = 0; c < 3; ++c)
        rgb_sum += std::abs(bilinear(b.rgb, ub, vb, c) - a.rgb.at<cv::Vec3b>(v, u)[c]);
    }
  }
  r.mean_abs_rgb = r.depth_agrees ? rgb_sum / (3.0 * r.depth_agrees) : 1e9;
  return r;
}

TEST(SyntheticScene, FramesHaveTheDocumentedTypesAndIntrinsics) {
  const SyntheticScene& s = test_scene();
  ASSERT_EQ(s.frames.size(), 10u);
  EXPECT_EQ(s.intrinsics.width, 384);
  EXPECT_EQ(s.intrinsics.height, 224);
  EXPECT_NEAR(s.intrinsics.fov_x_deg(), 70.0, 1e-9);
  for (size_t k = 0; k < s.frames.size(); ++k) {
    const SyntheticFrame& f = s.frames[k];
    EXPECT_EQ(f.rgb.type(), CV_8UC3);
    EXPECT_EQ(f.depth.type(), CV_32FC1);
    EXPECT_EQ(f.moving_mask.type(), CV_8UC1);
    EXPECT_EQ(f.rgb.size(), cv::Size(384, 224));
    EXPECT_EQ(f.depth.size(), cv::Size(384, 224));
    EXPECT_NEAR(f.timestamp, k / 30.0, 1e-12);
    EXPECT_NEAR((f.pose.R.transpose() * f.pose.R - Eigen::Matrix3d::Identity()).norm(), 0, 1e-9);
    EXPECT_NEAR(f.pose.R.determinant(), 1.0, 1e-9);
  }
}

// (c) The room is closed: every pixel sees a surface, at a depth inside the room's diagonal
// (6 x 2.8 x 8 m, so < 10.4 m).
TEST(SyntheticScene, DepthIsFinitePositiveEverywhere) {
  for (const SyntheticFrame& f : test_scene().frames) {
    double lo = 0, hi = 0;
    cv::minMaxLoc(f.depth, &lo, &hi);
    EXPECT_TRUE(cv::checkRange(f.depth)) << f.name;
    EXPECT_GT(lo, 0.1) << f.name;
    EXPECT_LT(hi, 10.4) << f.name;
  }
}

// (a) GT depth and poses agree with each other and with the images: static pixels reprojected
// between frames land on the same surface (depth within 1% for >= 90% of the pixels, the rest
// being occlusions and depth edges) and on the same colour (mean |diff| < 6 / 255; shading is
// Lambertian, so only resampling and mip-level blur differ).
TEST(SyntheticScene, GroundTruthIsGeometricallyConsistentAcrossFrames) {
  const SyntheticScene& s = test_scene();
  for (auto [i, j] : {std::pair{0, 1}, {0, 3}, {4, 9}, {7, 2}}) {
    const Reprojection r = reproject(s, i, j, s.frames[size_t(j)].pose);
    SCOPED_TRACE(::testing::Message() << "frames " << i << " -> " << j);
    std::printf(
        "frames %d -> %d: %zu pixels compared, %.2f%% with depth within 1%%, mean |rgb "
        "diff| %.2f\n",
        i, j, r.compared, 100.0 * r.depth_agrees / r.compared, r.mean_abs_rgb);
    ASSERT_GT(r.compared, size_t(0.4 * 384 * 224));  // the frames overlap substantially
    EXPECT_GE(double(r.depth_agrees) / r.compared, 0.90);
    EXPECT_LT(r.mean_abs_rgb, 6.0);
  }
}

// The check above can fail: a pose 10 cm off along the optical axis breaks the depth test, one
// 5 cm off sideways breaks the colour test.
TEST(SyntheticScene, ConsistencyCheckDetectsAWrongPose) {
  const SyntheticScene& s = test_scene();
  Pose forward = s.frames[3].pose, sideways = s.frames[3].pose;
  forward.t += forward.R * Eigen::Vector3d(0, 0, 0.10);
  sideways.t += sideways.R * Eigen::Vector3d(0.05, 0, 0);
  const Reprojection f = reproject(s, 0, 3, forward);
  EXPECT_LT(double(f.depth_agrees) / f.compared, 0.5);
  const Reprojection r = reproject(s, 0, 3, sideways);
  EXPECT_GT(r.mean_abs_rgb, 12.0);
}

// There is enough parallax for SfM: the camera centre moves by several % of the scene depth.
TEST(SyntheticScene, CameraPathHasParallax) {
  const SyntheticScene& s = test_scene();
  const double baseline = (s.frames.back().pose.t - s.frames.front().pose.t).norm();
  const double median_depth = [&] {
    cv::Mat sorted = s.frames.front().depth.reshape(1, 1).clone();
    cv::sort(sorted, sorted, cv::SORT_ASCENDING);
    return double(sorted.at<float>(0, sorted.cols / 2));
  }();
  EXPECT_GT(baseline / median_depth, 0.1);
  // Consecutive frames move smoothly: no step larger than 3x the mean step.
  double mean_step = baseline / (s.frames.size() - 1);
  for (size_t k = 1; k < s.frames.size(); ++k)
    EXPECT_LT((s.frames[k].pose.t - s.frames[k - 1].pose.t).norm(), 3 * mean_step);
}

// (b) Determinism.
TEST(SyntheticScene, SameSeedGivesIdenticalFramesAndOtherSeedsDiffer) {
  SyntheticSceneOptions o;
  o.width = 160;
  o.height = 96;
  o.frames = 4;
  const SyntheticScene a = render_synthetic_scene(o);
  const SyntheticScene b = render_synthetic_scene(o);
  o.seed = 2;
  const SyntheticScene c = render_synthetic_scene(o);
  for (size_t k = 0; k < a.frames.size(); ++k) {
    EXPECT_TRUE(identical(a.frames[k].rgb, b.frames[k].rgb)) << k;
    EXPECT_TRUE(identical(a.frames[k].depth, b.frames[k].depth)) << k;
    EXPECT_TRUE(identical(a.frames[k].moving_mask, b.frames[k].moving_mask)) << k;
    EXPECT_EQ(a.frames[k].pose.matrix(), b.frames[k].pose.matrix()) << k;
    EXPECT_FALSE(identical(a.frames[k].rgb, c.frames[k].rgb)) << k;
    EXPECT_GT(cv::norm(a.frames[k].rgb, c.frames[k].rgb, cv::NORM_L1) / a.frames[k].rgb.total(),
              10.0);
    EXPECT_GT((a.frames[k].pose.t - c.frames[k].pose.t).norm(), 1e-3) << k;
  }
  test::TempDir d1, d2;
  write_synthetic_scene(a, d1.path());
  write_synthetic_scene(b, d2.path());
  for (const char* f : {"rgb/frame_000002.png", "depth/frame_000002.pfm", "poses.txt"}) {
    std::ifstream f1(d1 / f, std::ios::binary), f2(d2 / f, std::ios::binary);
    const std::string s1((std::istreambuf_iterator<char>(f1)), {});
    const std::string s2((std::istreambuf_iterator<char>(f2)), {});
    EXPECT_FALSE(s1.empty()) << f;
    EXPECT_EQ(s1, s2) << f;
  }
}

// (d) Texture richness: feature detectors find plenty of keypoints spread over every frame, and
// no large area is flat.
TEST(SyntheticScene, FramesAreRichInFeatures) {
  auto orb = cv::ORB::create(3000);
  auto sift = cv::SIFT::create();
  for (const SyntheticFrame& f : test_scene().frames) {
    cv::Mat grey;
    cv::cvtColor(f.rgb, grey, cv::COLOR_BGR2GRAY);
    std::vector<cv::KeyPoint> orb_points, sift_points;
    orb->detect(grey, orb_points);
    sift->detect(grey, sift_points);
    EXPECT_GE(orb_points.size(), 800u) << f.name;
    EXPECT_GE(sift_points.size(), 400u) << f.name;
    // SIFT keypoints in at least 14 of the 16 cells of a 4x4 grid.
    bool cell_has_point[16] = {};
    for (const auto& k : sift_points)
      cell_has_point[std::min(3, int(k.pt.y * 4 / grey.rows)) * 4 +
                     std::min(3, int(k.pt.x * 4 / grey.cols))] = true;
    EXPECT_GE(std::count(std::begin(cell_has_point), std::end(cell_has_point), true), 14);
    // Every 16x16 block has some contrast (grey-level standard deviation > 3 levels) in >= 97%.
    int blocks = 0, flat = 0;
    for (int y = 0; y + 16 <= grey.rows; y += 16)
      for (int x = 0; x + 16 <= grey.cols; x += 16) {
        cv::Scalar mean, stddev;
        cv::meanStdDev(grey(cv::Rect(x, y, 16, 16)), mean, stddev);
        ++blocks;
        flat += stddev[0] <= 3.0;
      }
    EXPECT_LE(flat, blocks * 3 / 100) << f.name;
  }
}

// (f) The moving object is visible and moves relative to the static scene: the world position
// of its surface (unprojected with GT depth and pose) travels more than 1 m over the clip.
TEST(SyntheticScene, MovingObjectMovesInTheWorld) {
  const SyntheticScene& s = test_scene();
  const Intrinsics& K = s.intrinsics;
  std::vector<Eigen::Vector3d> centroids;
  for (const SyntheticFrame& f : s.frames) {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    int n = 0;
    for (int v = 0; v < K.height; ++v)
      for (int u = 0; u < K.width; ++u) {
        if (!f.moving_mask.at<uchar>(v, u)) continue;
        const double d = f.depth.at<float>(v, u);
        sum += f.pose.transform({d * (u - K.cx) / K.fx, d * (v - K.cy) / K.fy, d});
        ++n;
      }
    EXPECT_GT(n, 500) << f.name << ": the moving object should be clearly visible";
    if (n > 0) centroids.push_back(sum / n);
  }
  ASSERT_EQ(centroids.size(), s.frames.size());
  EXPECT_GT((centroids.back() - centroids.front()).norm(), 1.0);
  for (size_t k = 1; k < centroids.size(); ++k)
    EXPECT_GT((centroids[k] - centroids[k - 1]).norm(), 0.05)
        << "between frames " << k - 1 << " and " << k;

  SyntheticSceneOptions o;
  o.width = 96;
  o.height = 64;
  o.frames = 3;
  o.moving_object = false;
  for (const SyntheticFrame& f : render_synthetic_scene(o).frames)
    EXPECT_EQ(cv::countNonZero(f.moving_mask), 0);
}

TEST(SyntheticScene, RejectsBadOptions) {
  SyntheticSceneOptions o;
  o.frames = 1;
  EXPECT_THROW(render_synthetic_scene(o), Error);
  o = {};
  o.width = 8;
  EXPECT_THROW(render_synthetic_scene(o), Error);
  o = {};
  o.shake_rotation_deg = -1;
  EXPECT_THROW(render_synthetic_scene(o), Error);
}

TEST(SyntheticSceneFiles, WriteThenReadGivesTheGroundTruthBack) {
  const SyntheticScene& s = test_scene();
  test::TempDir dir;
  write_synthetic_scene(s, dir.path());
  const SceneGroundTruth gt = read_scene_ground_truth(dir.path());
  EXPECT_EQ(gt.intrinsics.fx, s.intrinsics.fx);
  EXPECT_EQ(gt.intrinsics.cy, s.intrinsics.cy);
  EXPECT_EQ(gt.intrinsics.width, s.intrinsics.width);
  EXPECT_EQ(gt.fps, 30.0);
  ASSERT_EQ(gt.frames.size(), s.frames.size());
  for (size_t k = 0; k < s.frames.size(); ++k) {
    EXPECT_EQ(gt.frames[k].name, s.frames[k].name);
    EXPECT_NEAR(gt.frames[k].timestamp, s.frames[k].timestamp, 1e-6);
    // TUM text keeps 9 decimals.
    EXPECT_LT((gt.frames[k].pose.matrix() - s.frames[k].pose.matrix()).cwiseAbs().maxCoeff(), 1e-7);
    EXPECT_TRUE(identical(gt.frames[k].depth, s.frames[k].depth));
    EXPECT_TRUE(identical(gt.frames[k].moving_mask, s.frames[k].moving_mask));
    EXPECT_TRUE(identical(read_color_image(gt.frames[k].rgb_path), s.frames[k].rgb));
  }
  // No temporary files are left behind.
  for (const auto& e : fs::recursive_directory_iterator(dir.path()))
    EXPECT_EQ(e.path().filename().string().find(".tmp"), std::string::npos) << e.path();
}

void expect_error(const std::function<void()>& f, ErrorCategory category,
                  const std::string& must_contain) {
  try {
    f();
    ADD_FAILURE() << "no error thrown; expected one containing '" << must_contain << "'";
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), category) << e.what();
    EXPECT_NE(std::string(e.what()).find(must_contain), std::string::npos) << e.what();
  }
}

TEST(SyntheticSceneFiles, ReaderRejectsBrokenFolders) {
  SyntheticSceneOptions o;
  o.width = 64;
  o.height = 48;
  o.frames = 3;
  const SyntheticScene s = render_synthetic_scene(o);
  auto fresh = [&](const test::TempDir& d) { write_synthetic_scene(s, d.path()); };
  {
    test::TempDir d;
    fresh(d);
    fs::remove(d / "depth/frame_000001.pfm");
    expect_error([&] { read_scene_ground_truth(d.path()); }, ErrorCategory::io, "frame_000001.pfm");
  }
  {
    test::TempDir d;
    fresh(d);
    std::ofstream(d / "poses.txt") << "0 0 0 0 0 0 0 1\n0.03 0 0 0 0 0 0 1\n";
    expect_error([&] { read_scene_ground_truth(d.path()); }, ErrorCategory::format, "2 poses");
  }
  {
    test::TempDir d;
    fresh(d);
    std::ofstream(d / "poses.txt") << "0 0 0 0 0 0 0 1\n0.03 0 0 0 0 0 0\n0.06 0 0 0 0 0 0 1\n";
    expect_error([&] { read_scene_ground_truth(d.path()); }, ErrorCategory::format, "line 2");
  }
  {
    test::TempDir d;
    fresh(d);
    std::ofstream(d / "intrinsics.json") << R"({"fx": 50, "fy": 50, "cx": 32, "width": 64})";
    expect_error([&] { read_scene_ground_truth(d.path()); }, ErrorCategory::format, "\"cy\"");
  }
  {
    test::TempDir d;
    fresh(d);
    cv::Mat bad = s.frames[2].depth.clone();
    bad.at<float>(5, 5) = -1;
    write_pfm(d / "depth/frame_000002.pfm", bad);
    expect_error([&] { read_scene_ground_truth(d.path()); }, ErrorCategory::format, "non-positive");
  }
  expect_error([] { read_scene_ground_truth("/nonexistent/cvd-scene"); }, ErrorCategory::io,
               "/nonexistent/cvd-scene");
}

TEST(SyntheticSceneCli, WritesAFolderTheReaderAccepts) {
  test::TempDir d;
  const auto ok = test::run_cvd("scene --out " + (d / "s").string() +
                                " --frames 3 --width 64 --height 48 --seed 7");
  ASSERT_EQ(ok.exit_code, 0) << ok.output;
  const SceneGroundTruth gt = read_scene_ground_truth(d / "s");
  EXPECT_EQ(gt.frames.size(), 3u);
  EXPECT_EQ(gt.intrinsics.width, 64);
  const auto bad = test::run_cvd("scene --out " + (d / "t").string() + " --frames 1");
  EXPECT_EQ(bad.exit_code, 2) << bad.output;
}

// ---- PFM ----------------------------------------------------------------------------------

void write_bytes(const fs::path& p, const std::string& bytes) {
  std::ofstream(p, std::ios::binary) << bytes;
}

std::string float_bytes(std::initializer_list<float> values, bool big_endian = false) {
  std::string s;
  for (float v : values) {
    char b[4];
    std::memcpy(b, &v, 4);
    if (big_endian) std::swap(b[0], b[3]), std::swap(b[1], b[2]);
    s.append(b, 4);
  }
  return s;
}

TEST(Pfm, RoundTripsOneAndThreeChannels) {
  test::TempDir d;
  cv::Mat grey(7, 5, CV_32FC1), color(4, 6, CV_32FC3);
  cv::randu(grey, -1e3, 1e3);
  cv::randu(color, -5, 5);
  grey.at<float>(1, 2) = std::numeric_limits<float>::infinity();
  grey.at<float>(3, 4) = std::numeric_limits<float>::quiet_NaN();
  write_pfm(d / "g.pfm", grey);
  write_pfm(d / "c.pfm", color);
  EXPECT_TRUE(identical(read_pfm(d / "g.pfm"), grey));
  EXPECT_TRUE(identical(read_pfm(d / "c.pfm"), color));
  // Header as the format says: "Pf", size, negative scale for little-endian.
  std::ifstream in(d / "g.pfm", std::ios::binary);
  std::string magic, scale;
  int w = 0, h = 0;
  in >> magic >> w >> h >> scale;
  EXPECT_EQ(magic, "Pf");
  EXPECT_EQ(w, 5);
  EXPECT_EQ(h, 7);
  EXPECT_EQ(scale, "-1");
  EXPECT_EQ(fs::file_size(d / "g.pfm"), std::string("Pf\n5 7\n-1\n").size() + 5 * 7 * 4);
}

// Files written by hand: rows bottom-to-top, R G B order, both byte orders.
TEST(Pfm, ReadsTheStandardLayout) {
  test::TempDir d;
  write_bytes(d / "g.pfm", "Pf\n2 2\n-1.0\n" + float_bytes({1, 2, 3, 4}));
  const cv::Mat g = read_pfm(d / "g.pfm");
  ASSERT_EQ(g.type(), CV_32FC1);
  EXPECT_EQ(g.at<float>(0, 0), 3);  // the top row is stored last
  EXPECT_EQ(g.at<float>(0, 1), 4);
  EXPECT_EQ(g.at<float>(1, 0), 1);
  write_bytes(d / "big.pfm", "Pf\n2 1\n1.0\n" + float_bytes({1.5f, -2.5f}, true));
  const cv::Mat big = read_pfm(d / "big.pfm");
  EXPECT_EQ(big.at<float>(0, 0), 1.5f);
  EXPECT_EQ(big.at<float>(0, 1), -2.5f);
  write_bytes(d / "c.pfm", "PF 1 1 -1\n" + float_bytes({10, 20, 30}));  // R, G, B
  const cv::Mat c = read_pfm(d / "c.pfm");
  ASSERT_EQ(c.type(), CV_32FC3);
  EXPECT_EQ(c.at<cv::Vec3f>(0, 0), cv::Vec3f(30, 20, 10));  // B, G, R
}

TEST(Pfm, RejectsMalformedFiles) {
  test::TempDir d;
  const std::string data4 = float_bytes({1, 2, 3, 4});
  const std::pair<std::string, std::string> cases[] = {
      {"P5\n2 2\n-1\n" + data4, "magic"},
      {"Pf\n0 2\n-1\n", "width 0"},
      {"Pf\n2 x\n-1\n" + data4, "height 'x'"},
      {"Pf\n2 2\nabc\n" + data4, "scale 'abc'"},
      {"Pf\n2 2\n0\n" + data4, "non-zero"},
      {"Pf\n2 2\n-1\n" + data4.substr(0, 10), "truncated"},
      {"Pf\n2 2\n-1\n" + data4 + "xx", "size mismatch"},
      {"Pf\n99999 2\n-1\n" + data4, "outside"},
      {"", "magic"},
  };
  for (const auto& [bytes, cause] : cases) {
    write_bytes(d / "bad.pfm", bytes);
    expect_error([&] { read_pfm(d / "bad.pfm"); }, ErrorCategory::format, cause);
    expect_error([&] { read_pfm(d / "bad.pfm"); }, ErrorCategory::format, "bad.pfm");
  }
  expect_error([&] { read_pfm(d / "missing.pfm"); }, ErrorCategory::io, "missing.pfm");
  EXPECT_THROW(write_pfm(d / "x.pfm", cv::Mat(2, 2, CV_8UC1)), Error);
  EXPECT_FALSE(fs::exists(d / "x.pfm"));
}

TEST(ImageIo, WritesAtomicallyAndReportsBadFiles) {
  test::TempDir d;
  cv::Mat img(10, 12, CV_8UC3, cv::Scalar(10, 20, 30));
  write_image(d / "a.png", img);
  EXPECT_TRUE(identical(read_color_image(d / "a.png"), img));
  cv::Mat mask(10, 12, CV_8UC1, cv::Scalar(255));
  write_image(d / "m.png", mask);
  EXPECT_TRUE(identical(read_single_channel_image(d / "m.png"), mask));
  expect_error([&] { read_single_channel_image(d / "a.png"); }, ErrorCategory::format,
               "3 channels");
  write_bytes(d / "broken.png", "\x89PNG not really");
  expect_error([&] { read_color_image(d / "broken.png"); }, ErrorCategory::format, "broken.png");
  expect_error([&] { read_color_image(d / "none.png"); }, ErrorCategory::io, "none.png");
  expect_error([&] { write_image(d / "x.unknownext", img); }, ErrorCategory::io, "x.unknownext");
  EXPECT_FALSE(fs::exists(d / "x.unknownext"));
  std::vector<fs::path> leftovers;
  for (const auto& e : fs::directory_iterator(d.path()))
    if (e.path().filename().string().find(".tmp") != std::string::npos) leftovers.push_back(e);
  EXPECT_TRUE(leftovers.empty());
}

}  // namespace
}  // namespace cvd
