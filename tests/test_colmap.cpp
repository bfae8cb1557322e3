// The COLMAP driver on real data (7-Scenes redkitchen, first 20 frames) and its failure modes.
// The real run needs the `colmap` binary and the shared data; it is skipped when either is absent.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "engine/error.h"
#include "pipeline/geometry/scale_calibration.h"
#include "pipeline/io/trajectory_io.h"
#include "pipeline/poses/colmap_known_poses.h"
#include "pipeline/poses/colmap_runner.h"
#include "test_support.h"

namespace cvd {
namespace {

namespace fs = std::filesystem;

#define CVD_REQUIRE_COLMAP()                                                                      \
  if (find_executable("colmap").empty()) {                                                        \
    GTEST_SKIP() << "colmap is not on PATH (Debian: apt install colmap); the driver is untested"; \
  }

// The kitchen frames the real-data tests use: every 6th of the first 115 (before the documented
// GT glitch at frame 121), 20 frames: 0.62 m of travel and 20.7 degrees of rotation.
constexpr int kKitchenFrames = 20, kKitchenStride = 6;
std::vector<ColmapFrame> kitchen_frames(const fs::path& data) {
  std::vector<fs::path> files;
  for (int i = 0; i < kKitchenFrames; ++i)
    files.push_back(data / "rgb" / fmt::format("frame-{:06d}.color.jpg", i * kKitchenStride));
  return load_colmap_frames(files);
}

// RMS distance between `a` and `b` after aligning a to b with a similarity (or, with
// with_scaling = false, a rigid) transform (Umeyama).
double aligned_rmse(const Eigen::Matrix3Xd& a, const Eigen::Matrix3Xd& b, bool with_scaling,
                    double* scale = nullptr) {
  Eigen::Matrix4d t = Eigen::umeyama(a, b, with_scaling);
  Eigen::Matrix3Xd moved = (t.topLeftCorner<3, 3>() * a).colwise() + t.topRightCorner<3, 1>();
  if (scale) *scale = std::cbrt(t.topLeftCorner<3, 3>().determinant());
  return std::sqrt((moved - b).colwise().squaredNorm().mean());
}

TEST(ColmapRunner, MissingBinaryIsAnUnsupportedError) {
  test::TempDir dir;
  std::vector<ColmapFrame> frames(3);
  for (int i = 0; i < 3; ++i) {
    frames[i].name = "f" + std::to_string(i) + ".png";
    frames[i].image = cv::Mat(48, 64, CV_8UC3, cv::Scalar(i * 40, 80, 120));
  }
  for (std::string binary : {"cvd-no-such-colmap-binary", "/nonexistent/dir/colmap"}) {
    ColmapOptions opt;
    opt.colmap_binary = binary;
    try {
      run_colmap(frames, dir / "work", opt);
      ADD_FAILURE() << "no error for colmap binary " << binary;
    } catch (const Error& e) {
      EXPECT_EQ(e.category(), ErrorCategory::unsupported);
      EXPECT_NE(std::string(e.what()).find("colmap not found on PATH"), std::string::npos)
          << e.what();
    }
  }
}

TEST(ColmapRunner, RejectsBadFramesBeforeRunningAnything) {
  test::TempDir dir;
  std::vector<ColmapFrame> frames(2);
  frames[0] = {"a.png", cv::Mat(48, 64, CV_8UC3, cv::Scalar::all(0)), {}};
  frames[1] = {"a.png", cv::Mat(48, 64, CV_8UC3, cv::Scalar::all(0)), {}};
  try {
    run_colmap(frames, dir / "work");
    ADD_FAILURE() << "duplicate names accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), ErrorCategory::invalid_argument);
    EXPECT_NE(std::string(e.what()).find("a.png"), std::string::npos);
  }
  frames[1] = {"b.png", cv::Mat(40, 64, CV_8UC3, cv::Scalar::all(0)), {}};
  EXPECT_THROW(run_colmap(frames, dir / "work"), Error);  // sizes differ
  frames[1].image = frames[0].image.clone();
  frames[1].mask = cv::Mat(10, 10, CV_8UC1, cv::Scalar(255));
  EXPECT_THROW(run_colmap(frames, dir / "work"), Error);  // mask of another size
  frames.resize(1);
  EXPECT_THROW(run_colmap(frames, dir / "work"), Error);  // one frame
  EXPECT_FALSE(fs::exists(dir / "work" / "colmap.log")) << "nothing may run on invalid input";
}

TEST(ColmapRunner, TexturelessClipIsAClearErrorNotACrash) {
  CVD_REQUIRE_COLMAP();
  test::TempDir dir;
  std::vector<ColmapFrame> frames;
  for (int i = 0; i < 4; ++i)
    frames.push_back({"blank_" + std::to_string(i) + ".png",
                      cv::Mat(120, 160, CV_8UC3, cv::Scalar(100, 100, 100)),
                      {}});
  try {
    run_colmap(frames, dir / "work");
    ADD_FAILURE() << "COLMAP registered a textureless clip";
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), ErrorCategory::external) << e.what();
    EXPECT_NE(std::string(e.what()).find("no model"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("colmap.log"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(fs::exists(dir / "work" / "colmap.log"));
}

TEST(ColmapRunner, RegistersTwentyKitchenFramesByNameWithTrueIntrinsics) {
  CVD_REQUIRE_COLMAP();
  CVD_REQUIRE_SHARED_DATA(data, "7scenes_redkitchen_f000000-000149");
  // 20 frames, every 6th of the first 115 (before the documented GT glitch at frame 121): 0.62 m
  // of travel and 20.7 degrees of rotation. Shorter spans are ill-conditioned: every 3rd frame
  // (0.25 m, 5.4 degrees) gave a reconstruction 16 degrees off in 3 of 5 runs (COLMAP's mapper is
  // multi-threaded and not repeatable); every 6th gave the same answer in 9 of 9 runs.
  constexpr int kFrames = kKitchenFrames, kStride = kKitchenStride;
  std::vector<ColmapFrame> frames = kitchen_frames(data);
  ASSERT_EQ(frames.size(), size_t(kFrames));
  EXPECT_EQ(frames[3].name, fmt::format("frame-{:06d}.color.jpg", 3 * kStride));

  test::TempDir dir;
  ColmapOptions opt;
  opt.intrinsics = Intrinsics{525.0, 525.0, 320.0, 240.0, 640, 480};
  // COLMAP sees 512x384 copies: this also checks that intrinsics and observations are scaled
  // back to the frames' 640x480.
  opt.max_image_size = 512;
  opt.max_num_features = 2048;  // keeps the test within ~3 minutes on 2 cores
  opt.sequential_overlap = 5;
  auto t0 = std::chrono::steady_clock::now();
  ColmapResult r = run_colmap(frames, dir / "work", opt);
  double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  RecordProperty("colmap_seconds", std::to_string(seconds));

  EXPECT_TRUE(r.unregistered.empty()) << r.unregistered.size() << " frames unregistered";
  ASSERT_EQ(r.cameras.size(), size_t(kFrames));
  for (int i = 0; i < kFrames; ++i) {
    EXPECT_EQ(r.cameras[i].name, frames[i].name);
    EXPECT_TRUE(r.cameras[i].registered) << frames[i].name;
    ASSERT_NE(r.model.find_image(frames[i].name), nullptr) << frames[i].name;
    // Intrinsics were given and kept fixed: they come back at 640x480 (tolerance: the 0.8
    // downscale round trip, printed with 6 decimals).
    EXPECT_NEAR(r.cameras[i].intrinsics.fx, 525.0, 1e-3);
    EXPECT_NEAR(r.cameras[i].intrinsics.cy, 240.0, 1e-3);
    EXPECT_EQ(r.cameras[i].intrinsics.width, 640);
  }
  EXPECT_GE(r.num_models, 1);
  EXPECT_GT(r.model.points.size(), 200u);
  EXPECT_TRUE(fs::exists(r.log_file));
  std::vector<std::string> steps;
  for (const auto& [step, s] : r.step_seconds) steps.push_back(step);
  ASSERT_GE(steps.size(), 4u);
  EXPECT_EQ(steps[0], "feature_extractor");
  EXPECT_EQ(steps[1], "sequential_matcher");
  EXPECT_EQ(steps[2], "mapper");
  // The saved copy of the chosen model carries the caller's names.
  ColmapModel saved = read_colmap_text_model(dir / "work" / "colmap_model_txt");
  EXPECT_EQ(saved.images.size(), size_t(kFrames));
  EXPECT_NE(saved.find_image(fmt::format("frame-{:06d}.color.jpg", 19 * kStride)), nullptr);

  // 2-D observations are in the 640x480 frame: reprojecting each observed point with the
  // returned pose and intrinsics lands near its observation (tolerance 4 px: COLMAP's
  // reprojection errors are ~1 px at 512x384 and scale by 1.25).
  int checked = 0, close = 0;
  for (const auto& [name, img] : r.model.images) {
    const Intrinsics k = r.model.cameras.at(img.camera_id).intrinsics();
    for (const auto& o : img.observations) {
      if (o.point3d_id < 0) continue;
      Eigen::Vector3d xc = img.pose.inverse().transform(r.model.points.at(o.point3d_id).xyz);
      Eigen::Vector2d p(k.fx * xc.x() / xc.z() + k.cx, k.fy * xc.y() / xc.z() + k.cy);
      ++checked;
      close += (p - o.xy).norm() < 4.0;
    }
  }
  ASSERT_GT(checked, 500);
  EXPECT_GT(double(close) / checked, 0.95);

  // Trajectory vs ground truth after Sim(3) alignment, matched by name (frame-K <-> GT line K).
  auto gt = read_tum_trajectory(data / "groundtruth_rgb.txt");
  Eigen::Matrix3Xd est(3, kFrames), ref(3, kFrames);
  for (int i = 0; i < kFrames; ++i) {
    est.col(i) = r.cameras[i].pose.t;
    ref.col(i) = gt[i * kStride].pose.t;
  }
  // Rotations relative to the first frame agree with GT (a centre-only ATE on a short, nearly
  // straight path cannot see a rotation / translation ambiguity; this can). Measured: 3.4 degrees
  // worst over 20.7 degrees of rotation in every run. That error is systematic: the dataset's
  // intrinsics are nominal (COLMAP refines f to 551 px against the nominal 525) and the RGB poses
  // come through a nominal depth->RGB extrinsic. Tolerance 5 degrees; the wrong reconstructions
  // seen while tuning were 10-16 degrees off.
  double worst_rotation_deg = 0;
  for (int i = 1; i < kFrames; ++i) {
    Eigen::Matrix3d est_rel = r.cameras[0].pose.R.transpose() * r.cameras[i].pose.R;
    Eigen::Matrix3d gt_rel = gt[0].pose.R.transpose() * gt[i * kStride].pose.R;
    double deg = Eigen::AngleAxisd(est_rel * gt_rel.transpose()).angle() * 180.0 / M_PI;
    worst_rotation_deg = std::max(worst_rotation_deg, deg);
  }
  RecordProperty("worst_relative_rotation_error_deg", std::to_string(worst_rotation_deg));
  EXPECT_LT(worst_rotation_deg, 5.0);
  double sim3_scale = 0;
  double ate = aligned_rmse(est, ref, true, &sim3_scale);
  RecordProperty("ate_m", std::to_string(ate));
  // Measured: ATE ~1 cm over the 0.62 m path (the GT is KinectFusion, itself cm-level);
  // threshold 2 cm leaves room for run-to-run variation.
  EXPECT_LT(ate, 0.02) << "ATE after Sim(3) alignment, metres";

  // Scale calibration with the measured depth as the "network": frames agree on one scale, and
  // the calibrated trajectory matches GT with a RIGID alignment (no scale left to fit) because
  // poses are then in the depth map's units (metres).
  std::vector<cv::Mat> depths;
  for (int i = 0; i < kFrames; ++i) {
    cv::Mat mm =
        cv::imread((data / "depth" / fmt::format("frame-{:06d}.depth.png", i * kStride)).string(),
                   cv::IMREAD_UNCHANGED);
    ASSERT_EQ(mm.type(), CV_16UC1);
    cv::Mat metres;
    mm.convertTo(metres, CV_32F, 1.0 / 1000.0);
    depths.push_back(metres);
  }
  ScaleCalibrationResult cal = calibrate_scale(r.cameras, depths, r.model);
  EXPECT_EQ(cal.num_valid(), kFrames);
  // The mean per-frame scale (metres per COLMAP unit) equals the Sim(3) scale COLMAP -> GT.
  // Measured 10% apart: with the focal length fixed 5% below what the images support, the
  // reconstruction's depth-to-baseline ratio is off by about that much. Tolerance 15%; a scale
  // computed from the wrong frames or pixels is off by far more.
  EXPECT_NEAR(cal.scale, sim3_scale, 0.15 * sim3_scale);
  for (int i = 0; i < kFrames; ++i)
    EXPECT_NEAR(cal.frame_scales[i], cal.scale, 0.05 * cal.scale) << frames[i].name;
  for (int i = 0; i < kFrames; ++i) est.col(i) = cal.cameras[i].pose.t;
  double rigid_ate = aligned_rmse(est, ref, false);
  RecordProperty("calibrated_rigid_ate_m", std::to_string(rigid_ate));
  RecordProperty("sim3_scale", std::to_string(sim3_scale));
  RecordProperty("calibrated_scale", std::to_string(cal.scale));
  EXPECT_LT(rigid_ate, 0.04) << "calibrated trajectory vs GT after a rigid alignment, metres";
}

TEST(ColmapRunner, KeyframesAreMappedAndTheOtherFramesRegisteredToThem) {
  CVD_REQUIRE_COLMAP();
  CVD_REQUIRE_SHARED_DATA(data, "7scenes_redkitchen_f000000-000149");
  // The frames of the test above at a smaller size and budget; 8 keyframes for the mapper, the
  // other 12 registered afterwards (image_registrator) and one bundle adjustment.
  constexpr int kFrames = kKitchenFrames, kStride = kKitchenStride;
  std::vector<ColmapFrame> frames = kitchen_frames(data);
  test::TempDir dir;
  ColmapOptions opt;
  opt.intrinsics = Intrinsics{525.0, 525.0, 320.0, 240.0, 640, 480};
  opt.max_image_size = 384;
  opt.max_num_features = 1024;
  opt.sequential_overlap = 3;
  opt.keyframes = parse_keyframe_mode("8", "test");
  ColmapResult r = run_colmap(frames, dir / "work", opt);
  ASSERT_EQ(r.keyframes.size(), 8u);
  EXPECT_EQ(r.keyframes.front(), frames.front().name);
  EXPECT_EQ(r.keyframes.back(), frames.back().name);
  EXPECT_GT(r.matched_pairs, 0);
  std::vector<std::string> steps;
  for (const auto& [step, s] : r.step_seconds) steps.push_back(step);
  for (const char* want : {"matches_importer", "mapper", "image_registrator", "bundle_adjuster"})
    EXPECT_NE(std::find(steps.begin(), steps.end(), want), steps.end()) << want;
  // Every frame has a pose, keyframe or not, and they agree with the ground truth.
  EXPECT_TRUE(r.unregistered.empty()) << r.unregistered.size() << " frames unregistered";
  auto gt = read_tum_trajectory(data / "groundtruth_rgb.txt");
  Eigen::Matrix3Xd est(3, kFrames), ref(3, kFrames);
  double worst_rotation_deg = 0;
  for (int i = 0; i < kFrames; ++i) {
    ASSERT_TRUE(r.cameras[i].registered) << frames[i].name;
    est.col(i) = r.cameras[i].pose.t;
    ref.col(i) = gt[i * kStride].pose.t;
    Eigen::Matrix3d est_rel = r.cameras[0].pose.R.transpose() * r.cameras[i].pose.R;
    Eigen::Matrix3d gt_rel = gt[0].pose.R.transpose() * gt[i * kStride].pose.R;
    worst_rotation_deg = std::max(
        worst_rotation_deg, Eigen::AngleAxisd(est_rel * gt_rel.transpose()).angle() * 180.0 / M_PI);
  }
  // Same tolerances as with every frame mapped (above): 5 degrees, 2 cm ATE.
  EXPECT_LT(worst_rotation_deg, 5.0);
  EXPECT_LT(aligned_rmse(est, ref, true), 0.02) << "ATE after Sim(3) alignment, metres";
}

TEST(ColmapRunner, PointsTriangulatedWithGivenPosesMatchTheMeasuredDepth) {
  CVD_REQUIRE_COLMAP();
  CVD_REQUIRE_SHARED_DATA(data, "7scenes_redkitchen_f000000-000149");
  // The ground-truth poses held fixed: the points come back in metres, where the measured depth
  // can check them directly (no scale to fit).
  constexpr int kFrames = kKitchenFrames, kStride = kKitchenStride;
  std::vector<ColmapFrame> frames = kitchen_frames(data);
  auto gt = read_tum_trajectory(data / "groundtruth_rgb.txt");
  const Intrinsics K{525.0, 525.0, 320.0, 240.0, 640, 480};
  std::vector<NamedCamera> cams;
  for (int i = 0; i < kFrames; ++i)
    cams.push_back({frames[i].name, gt[i * kStride].pose, K, true, 0});
  cams[7].registered = false;  // a frame without a pose is left out
  test::TempDir dir;
  ColmapOptions opt;
  opt.intrinsics = K;
  opt.max_image_size = 384;
  opt.max_num_features = 1024;
  opt.sequential_overlap = 3;
  ColmapResult r;
  ColmapModel m = triangulate_known_poses(frames, cams, dir / "work", opt, r);
  EXPECT_EQ(m.find_image(frames[7].name), nullptr);
  ASSERT_GT(m.points.size(), 300u);
  std::vector<double> rel;
  int checked = 0, close = 0;
  for (int i = 0; i < kFrames; ++i) {
    if (i == 7) continue;
    const ColmapImage* img = m.find_image(frames[i].name);
    ASSERT_NE(img, nullptr) << frames[i].name;
    // The poses are the given ones.
    EXPECT_LT((img->pose.t - cams[i].pose.t).norm(), 1e-5);
    cv::Mat mm =
        cv::imread((data / "depth" / fmt::format("frame-{:06d}.depth.png", i * kStride)).string(),
                   cv::IMREAD_UNCHANGED);
    ASSERT_EQ(mm.type(), CV_16UC1);
    for (const auto& o : img->observations) {
      if (o.point3d_id < 0) continue;
      Eigen::Vector3d xc = cams[i].pose.inverse().transform(m.points.at(o.point3d_id).xyz);
      Eigen::Vector2d p(K.fx * xc.x() / xc.z() + K.cx, K.fy * xc.y() / xc.z() + K.cy);
      ++checked;
      close += (p - o.xy).norm() < 4.0;
      int u = int(std::lround(o.xy.x())), v = int(std::lround(o.xy.y()));
      if (u < 0 || v < 0 || u >= mm.cols || v >= mm.rows) continue;
      double measured = mm.at<uint16_t>(v, u) / 1000.0;
      if (measured > 0.1) rel.push_back(std::abs(xc.z() - measured) / measured);
    }
  }
  ASSERT_GT(checked, 500);
  EXPECT_GT(double(close) / checked, 0.95);
  ASSERT_GT(rel.size(), 300u);
  std::nth_element(rel.begin(), rel.begin() + rel.size() / 2, rel.end());
  // Median relative error against the Kinect depth, with no scale fitted. The RGB poses come
  // through a nominal depth->RGB extrinsic (see above), so a few percent is expected; flow tracks
  // on the same poses score ~6% (README, 7-Scenes frames 0-39).
  EXPECT_LT(rel[rel.size() / 2], 0.06) << "median |z - measured| / measured over " << rel.size();
  RecordProperty("median_relative_depth_error", std::to_string(rel[rel.size() / 2]));
}

// `cvd run` reuses its cached COLMAP model only when it was made from the same frames and
// settings: another feature budget (or masks, intrinsics, matcher) runs COLMAP again.
TEST(ColmapRunner, CachedModelIsReusedOnlyWithTheSameSettings) {
  CVD_REQUIRE_COLMAP();
  test::TempDir dir;
  const fs::path scene = dir.path() / "scene";
  test::CommandResult r =
      test::run_cvd("scene --out '" + scene.string() + "' --frames 8 --width 256 --height 160");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::ifstream kf(scene / "intrinsics.json");
  auto k = nlohmann::json::parse(kf);
  const std::string args =
      "run '" + (scene / "rgb").string() + "' -o '" + (dir.path() / "out").string() +
      "' --epochs 1 --warmup 1 --width 0.0625 --depth-size 64 --no-videos --no-ply "
      "--intrinsics " +
      fmt::format("{:.17g},{:.17g},{:.17g},{:.17g}", k["fx"].get<double>(), k["fy"].get<double>(),
                  k["cx"].get<double>(), k["cy"].get<double>());
  r = test::run_cvd(args + " --colmap-features 1024");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = test::run_cvd(args + " --colmap-features 1024");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("poses: cached COLMAP model"), std::string::npos) << r.output;
  r = test::run_cvd(args + " --colmap-features 1500");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("made with other settings; running again"), std::string::npos)
      << r.output;
  EXPECT_EQ(r.output.find("poses: cached COLMAP model"), std::string::npos) << r.output;
  // New poses: the training checkpoint of the earlier poses is not resumed.
  EXPECT_NE(r.output.find("training starts over"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace cvd
