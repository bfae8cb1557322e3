// Pose files: trajectory (TUM, KITTI), COLMAP model and intrinsics JSON reading and writing, and
// a run's poses.txt taken back by another run. (Pair sampling and the scale calibration:
// test_scale_calibration.cpp; the COLMAP driver: test_colmap.cpp.)
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

Pose random_pose(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Quaterniond q(n(rng), n(rng), n(rng), n(rng));
  q.normalize();
  Pose p;
  p.R = q.toRotationMatrix();
  p.t = Eigen::Vector3d(n(rng), n(rng), n(rng)) * 3.0;
  return p;
}

void write_file(const fs::path& p, const std::string& content) {
  std::ofstream out(p);
  out << content;
}

// Expects Error(format) whose message names "<file>:<line>".
template <class F>
void expect_format_error(F&& f, const fs::path& file, int line, const std::string& also = "") {
  try {
    f();
    ADD_FAILURE() << "no error thrown for " << file << " line " << line;
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), ErrorCategory::format) << e.what();
    std::string where = file.string() + ":" + std::to_string(line) + ":";
    EXPECT_NE(std::string(e.what()).find(where), std::string::npos)
        << "message '" << e.what() << "' does not name " << where;
    if (!also.empty()) {
      EXPECT_NE(std::string(e.what()).find(also), std::string::npos) << e.what();
    }
  }
}

// Tolerances: values are written in shortest round-trip form, so a round trip is exact up to the
// quaternion <-> matrix conversion (1e-12).
constexpr double kRoundTripTol = 1e-12;

// ---- TUM ----------------------------------------------------------------------------------------

TEST(TumTrajectory, RoundTripIsExactAndWritesNoTemporaryFiles) {
  test::TempDir dir;
  std::mt19937 rng(1);
  std::vector<TimedPose> poses;
  for (int i = 0; i < 25; ++i) poses.push_back({i / 30.0 + 1e-7 * i, random_pose(rng)});
  write_tum_trajectory(dir / "traj.txt", poses);
  auto back = read_tum_trajectory(dir / "traj.txt");
  ASSERT_EQ(back.size(), poses.size());
  for (size_t i = 0; i < poses.size(); ++i) {
    EXPECT_EQ(back[i].timestamp, poses[i].timestamp);
    EXPECT_LT((back[i].pose.R - poses[i].pose.R).norm(), kRoundTripTol);
    EXPECT_LT((back[i].pose.t - poses[i].pose.t).norm(), kRoundTripTol);
  }
  int files = 0;
  for ([[maybe_unused]] auto& e : fs::directory_iterator(dir.path())) ++files;
  EXPECT_EQ(files, 1);
}

TEST(TumTrajectory, ReadsCameraToWorldWithQuaternionLast) {
  test::TempDir dir;
  // 90 degrees about z: qx qy qz qw = 0 0 sin45 cos45.
  write_file(dir / "t.txt", "# a comment\n\n1.5 1 2 3 0 0 0.7071067811865476 0.7071067811865476\n");
  auto p = read_tum_trajectory(dir / "t.txt");
  ASSERT_EQ(p.size(), 1u);
  EXPECT_DOUBLE_EQ(p[0].timestamp, 1.5);
  EXPECT_LT((p[0].pose.t - Eigen::Vector3d(1, 2, 3)).norm(), 1e-15);
  // Camera x axis maps to world y.
  EXPECT_LT((p[0].pose.R * Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitY()).norm(), 1e-12);
}

TEST(TumTrajectory, RejectsMalformedLinesNamingFileAndLine) {
  test::TempDir dir;
  const std::string good = "0 0 0 0 0 0 0 1\n";
  struct Case {
    std::string bad_line;
    std::string expect;
  };
  std::vector<Case> cases = {
      {"1 2 3 4 5 6 7", "expected 8 numbers"},    {"1 2 3 4 5 6 7 8 9", "expected 8 numbers"},
      {"1 2 x 4 0 0 0 1", "'x' is not a number"}, {"1 2 3 4 0 0 0 2", "norm"},
      {"1 2 nan 4 0 0 0 1", "not finite"},        {"1 2 3 4 0 0 0 1junk", "not a number"},
  };
  for (size_t c = 0; c < cases.size(); ++c) {
    fs::path f = dir / ("bad" + std::to_string(c) + ".txt");
    write_file(f, "# header\n" + good + cases[c].bad_line + "\n" + good);
    expect_format_error([&] { read_tum_trajectory(f); }, f, 3, cases[c].expect);
  }
  try {
    read_tum_trajectory(dir / "absent.txt");
    ADD_FAILURE() << "no error for a missing file";
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), ErrorCategory::io);
    EXPECT_NE(std::string(e.what()).find("absent.txt"), std::string::npos);
  }
}

TEST(TumTrajectory, Reads7ScenesGroundTruth) {
  CVD_REQUIRE_SHARED_DATA(data, "7scenes_redkitchen_f000000-000149");
  auto poses = read_tum_trajectory(data / "groundtruth_rgb.txt");
  ASSERT_EQ(poses.size(), 150u);
  // First line of the file: 0.000000 -0.3165422 0.0093614 0.3024787 ...; timestamps i / 30.
  EXPECT_NEAR(poses[0].pose.t.x(), -0.3165422, 1e-9);
  EXPECT_NEAR(poses[0].pose.t.z(), 0.3024787, 1e-9);
  for (size_t i = 0; i < poses.size(); ++i) {
    EXPECT_NEAR(poses[i].timestamp, i / 30.0, 1e-6);
    EXPECT_LT((poses[i].pose.R.transpose() * poses[i].pose.R - Eigen::Matrix3d::Identity()).norm(),
              1e-9);
  }
  // README: camera path length 1.07 m.
  double path = 0;
  for (size_t i = 1; i < poses.size(); ++i) path += (poses[i].pose.t - poses[i - 1].pose.t).norm();
  EXPECT_NEAR(path, 1.07, 0.01);
}

// ---- KITTI --------------------------------------------------------------------------------------

TEST(KittiTrajectory, RoundTripIsExact) {
  test::TempDir dir;
  std::mt19937 rng(2);
  std::vector<Pose> poses;
  for (int i = 0; i < 12; ++i) poses.push_back(random_pose(rng));
  write_kitti_trajectory(dir / "k.txt", poses);
  auto back = read_kitti_trajectory(dir / "k.txt");
  ASSERT_EQ(back.size(), poses.size());
  for (size_t i = 0; i < poses.size(); ++i) {
    EXPECT_LT((back[i].R - poses[i].R).norm(), kRoundTripTol);
    EXPECT_LT((back[i].t - poses[i].t).norm(), kRoundTripTol);
  }
  // Row-major 3x4: the 4th, 8th and 12th numbers are the translation.
  write_file(dir / "one.txt", "1 0 0 7 0 1 0 8 0 0 1 9\n");
  auto one = read_kitti_trajectory(dir / "one.txt");
  ASSERT_EQ(one.size(), 1u);
  EXPECT_EQ(one[0].t, Eigen::Vector3d(7, 8, 9));
}

TEST(KittiTrajectory, RejectsMalformedLinesNamingFileAndLine) {
  test::TempDir dir;
  const std::string good = "1 0 0 0 0 1 0 0 0 0 1 0\n";
  std::vector<std::pair<std::string, std::string>> cases = {
      {"1 0 0 0 0 1 0 0 0 0 1", "expected 12 numbers"},
      {"2 0 0 0 0 1 0 0 0 0 1 0", "not a rotation"},
      {"-1 0 0 0 0 1 0 0 0 0 1 0", "not a rotation"},  // a reflection
      {"1 0 0 0 0 1 0 0 0 0 1 inf", "not finite"},
  };
  for (size_t c = 0; c < cases.size(); ++c) {
    fs::path f = dir / ("bad" + std::to_string(c) + ".txt");
    write_file(f, good + good + cases[c].first + "\n");
    expect_format_error([&] { read_kitti_trajectory(f); }, f, 3, cases[c].second);
  }
}

// ---- COLMAP -------------------------------------------------------------------------------------

TEST(ColmapModel, ConvertsWorldToCameraOnAHandMadeExample) {
  test::TempDir dir;
  // One camera, one image: q = (cos45, 0, 0, sin45) is R_cw = 90 degrees about z, t_cw = (1,2,3).
  // R_cw = [0 -1 0; 1 0 0; 0 0 1]  ->  camera centre C = -R_cw^T t_cw = (-2, 1, -3).
  write_file(dir / "cameras.txt", "# c\n1 SIMPLE_PINHOLE 640 480 500 320 240\n");
  write_file(dir / "images.txt",
             "# i\n7 0.7071067811865476 0 0 0.7071067811865476 1 2 3 1 my frame 01.png\n"
             "10 20 42 30.5 40.5 -1\n");
  write_file(dir / "points3D.txt", "42 -2 1 2 255 128 0 0.5 7 0\n");
  ColmapModel m = read_colmap_text_model(dir.path());
  ASSERT_EQ(m.images.size(), 1u);
  const ColmapImage* img = m.find_image("my frame 01.png");
  ASSERT_NE(img, nullptr) << "image names may contain spaces";
  Eigen::Matrix3d r_cw;
  r_cw << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  EXPECT_LT((img->pose.R - r_cw.transpose()).norm(), 1e-12);
  EXPECT_LT((img->pose.t - Eigen::Vector3d(-2, 1, -3)).norm(), 1e-12);
  // The point (-2, 1, 2) lies 5 units straight ahead of the camera centre along world z, which is
  // camera z: it projects to the principal point with depth 5.
  const Eigen::Vector3d xw(-2, 1, 2);
  Eigen::Vector3d xc = img->pose.inverse().transform(xw);
  EXPECT_LT((xc - Eigen::Vector3d(0, 0, 5)).norm(), 1e-12);
  EXPECT_LT((r_cw * xw + Eigen::Vector3d(1, 2, 3) - xc).norm(), 1e-12);
  // Observations, points and the track.
  ASSERT_EQ(img->observations.size(), 2u);
  EXPECT_EQ(img->observations[0].point3d_id, 42);
  EXPECT_EQ(img->observations[1].point3d_id, -1);
  EXPECT_EQ(img->observations[1].xy, Eigen::Vector2d(30.5, 40.5));
  ASSERT_EQ(m.points.count(42), 1u);
  EXPECT_EQ(m.points.at(42).rgb[1], 128);
  EXPECT_DOUBLE_EQ(m.points.at(42).error, 0.5);
  ASSERT_EQ(m.points.at(42).track.size(), 1u);
  EXPECT_EQ(m.points.at(42).track[0].image_id, 7);
  auto obs = m.observed_points("my frame 01.png");
  ASSERT_EQ(obs.size(), 1u);
  EXPECT_EQ(obs[0], xw);
  NamedCamera fc = m.frame_camera("my frame 01.png");
  EXPECT_TRUE(fc.registered);
  EXPECT_DOUBLE_EQ(fc.intrinsics.fx, 500);
  EXPECT_DOUBLE_EQ(fc.intrinsics.fy, 500);
  EXPECT_DOUBLE_EQ(fc.intrinsics.cx, 320);
  EXPECT_EQ(fc.intrinsics.width, 640);
  EXPECT_FALSE(m.frame_camera("other.png").registered);
  EXPECT_TRUE(m.notes.empty());
}

TEST(ColmapModel, RoundTripKeepsEverythingAndNotesIgnoredDistortion) {
  test::TempDir dir;
  std::mt19937 rng(3);
  ColmapModel m;
  m.cameras[1] = {1, "SIMPLE_RADIAL", 640, 480, {520.5, 319.5, 239.5, 0.01}};
  m.cameras[2] = {2, "PINHOLE", 320, 240, {260, 261, 160, 120}};
  m.cameras[3] = {3, "OPENCV", 100, 80, {90, 91, 50, 40, 0, 0, 0, 0}};
  for (int i = 0; i < 5; ++i) {
    ColmapImage img;
    img.id = 10 + i;
    img.name = "frame_" + std::to_string(i) + ".jpg";
    img.camera_id = 1 + i % 3;
    img.pose = random_pose(rng);
    for (int k = 0; k < 4; ++k) img.observations.push_back({{k * 1.25, k * 2.5}, k == 3 ? -1 : k});
    m.images[img.name] = img;
  }
  for (int k = 0; k < 3; ++k) {
    ColmapPoint p;
    p.id = k;
    p.xyz = Eigen::Vector3d(k, -k * 0.5, 2.0 + k);
    p.rgb = {uint8_t(k), 2, 3};
    p.error = 0.25 * k;
    for (int i = 0; i < 5; ++i) p.track.push_back({10 + i, k});
    m.points[k] = p;
  }
  write_colmap_text_model(dir / "model", m);
  ColmapModel b = read_colmap_text_model(dir / "model");
  ASSERT_EQ(b.cameras.size(), 3u);
  for (const auto& [id, c] : m.cameras) {
    EXPECT_EQ(b.cameras.at(id).model, c.model);
    EXPECT_EQ(b.cameras.at(id).params, c.params);
    EXPECT_EQ(b.cameras.at(id).width, c.width);
  }
  EXPECT_DOUBLE_EQ(b.cameras.at(1).intrinsics().fy, 520.5);
  EXPECT_DOUBLE_EQ(b.cameras.at(2).intrinsics().fy, 261);
  ASSERT_EQ(b.images.size(), 5u);
  for (const auto& [name, img] : m.images) {
    const ColmapImage* r = b.find_image(name);
    ASSERT_NE(r, nullptr);
    EXPECT_EQ(r->id, img.id);
    EXPECT_EQ(r->camera_id, img.camera_id);
    EXPECT_LT((r->pose.R - img.pose.R).norm(), kRoundTripTol);
    EXPECT_LT((r->pose.t - img.pose.t).norm(), 1e-11);
    ASSERT_EQ(r->observations.size(), img.observations.size());
    for (size_t k = 0; k < img.observations.size(); ++k) {
      EXPECT_EQ(r->observations[k].xy, img.observations[k].xy);
      EXPECT_EQ(r->observations[k].point3d_id, img.observations[k].point3d_id);
    }
  }
  ASSERT_EQ(b.points.size(), 3u);
  EXPECT_EQ(b.points.at(2).xyz, m.points.at(2).xyz);
  EXPECT_EQ(b.points.at(2).track.size(), 5u);
  EXPECT_EQ(b.points.at(1).rgb, m.points.at(1).rgb);
  // SIMPLE_RADIAL with k != 0 is noted; OPENCV with all-zero distortion is not.
  ASSERT_EQ(b.notes.size(), 1u);
  EXPECT_NE(b.notes[0].find("SIMPLE_RADIAL"), std::string::npos);
}

TEST(ColmapModel, FromFramesWritesRegisteredFramesOnly) {
  test::TempDir dir;
  std::mt19937 rng(4);
  Intrinsics k{525, 525, 320, 240, 640, 480};
  std::vector<NamedCamera> frames = {{"a.png", random_pose(rng), k, true, 0},
                                     {"b.png", random_pose(rng), k, false, 0},
                                     {"c.png", random_pose(rng), k, true, 0}};
  write_colmap_text_model(dir.path(), colmap_model_from_frames(frames));
  ColmapModel m = read_colmap_text_model(dir.path());
  EXPECT_EQ(m.cameras.size(), 1u);
  EXPECT_EQ(m.images.size(), 2u);
  EXPECT_EQ(m.find_image("b.png"), nullptr);
  NamedCamera c = m.frame_camera("c.png");
  EXPECT_LT((c.pose.t - frames[2].pose.t).norm(), 1e-11);
  EXPECT_DOUBLE_EQ(c.intrinsics.fx, 525);
}

TEST(ColmapModel, RejectsMalformedFilesNamingFileAndLine) {
  const std::string cams = "# h\n1 PINHOLE 640 480 500 500 320 240\n";
  const std::string imgs = "# h\n1 1 0 0 0 0 0 0 1 a.png\n1 2 5\n";
  const std::string pts = "# h\n5 0 0 1 1 2 3 0.1 1 0\n";
  struct Case {
    std::string cameras, images, points;
    std::string bad_file;
    int line;
    std::string expect;
  };
  std::vector<Case> cases = {
      {"# h\n1 NOPE 640 480 1 2 3\n", imgs, pts, "cameras.txt", 2, "unknown camera model"},
      {"# h\n1 PINHOLE 640 480 500 320 240\n", imgs, pts, "cameras.txt", 2, "4 parameters"},
      {"# h\n1 PINHOLE 640 -480 500 500 320 240\n", imgs, pts, "cameras.txt", 2, "not positive"},
      {cams, "# h\n1 1 0 0 0 0 0 zero 1 a.png\n\n", pts, "images.txt", 2, "not a number"},
      {cams, "# h\n1 1 0 0 0 0 0 0 2 a.png\n\n", pts, "images.txt", 2, "camera 2"},
      {cams, "# h\n1 1 0 0 0 0 0 0 1\n\n", pts, "images.txt", 2, "expected IMAGE_ID"},
      {cams, "# h\n1 1 0 0 0 0 0 0 1 a.png\n1 2\n", pts, "images.txt", 3, "triples"},
      {cams, "# h\n1 1 0 0 0 0 0 0 1 a.png\n1 2 x\n", pts, "images.txt", 3, "integer"},
      {cams, "# h\n1 3 0 0 0 0 0 0 1 a.png\n\n", pts, "images.txt", 2, "norm"},
      {cams, imgs, "# h\n5 0 0 1 1 2 3 0.1 9 0\n", "points3D.txt", 2, "image 9"},
      {cams, imgs, "# h\n5 0 0 1 300 2 3 0.1 1 0\n", "points3D.txt", 2, "0..255"},
      {cams, imgs, "# h\n\n5 0 0 1 1 2 3 0.1 1\n", "points3D.txt", 3, "pairs"},
  };
  for (size_t c = 0; c < cases.size(); ++c) {
    test::TempDir dir;
    write_file(dir / "cameras.txt", cases[c].cameras);
    write_file(dir / "images.txt", cases[c].images);
    write_file(dir / "points3D.txt", cases[c].points);
    SCOPED_TRACE("case " + std::to_string(c));
    expect_format_error([&] { read_colmap_text_model(dir.path()); }, dir / cases[c].bad_file,
                        cases[c].line, cases[c].expect);
  }
  // The valid combination reads, and a missing images.txt is an io error naming it.
  test::TempDir dir;
  write_file(dir / "cameras.txt", cams);
  write_file(dir / "images.txt", imgs);
  write_file(dir / "points3D.txt", pts);
  EXPECT_EQ(read_colmap_text_model(dir.path()).points.size(), 1u);
  fs::remove(dir / "images.txt");
  try {
    read_colmap_text_model(dir.path());
    ADD_FAILURE() << "no error for a missing images.txt";
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), ErrorCategory::io);
    EXPECT_NE(std::string(e.what()).find("images.txt"), std::string::npos);
  }
}

// Found by the 1 M-execution run of tests/fuzz/fuzz_colmap_text: a '\r' between two fields of an
// image line split the fields but not the name search, which then threw std::out_of_range (not a
// cvd::Error). Any whitespace now separates fields in both.
TEST(ColmapModel, CarriageReturnInsideAnImageLineSeparatesFieldsLikeASpace) {
  test::TempDir dir;
  write_file(dir / "cameras.txt", "# h\n1 PINHOLE 640 480 500 500 320 240\n");
  write_file(dir / "images.txt", "# h\n1 1 0 0 0 0.5\r0 0 1 a.png\n\n");
  write_file(dir / "points3D.txt", "");
  const ColmapModel m = read_colmap_text_model(dir.path());
  ASSERT_EQ(m.images.size(), 1u);
  EXPECT_EQ(m.images.begin()->first, "a.png");
  // A line whose fields end before the name is a format error naming the line, not a crash.
  write_file(dir / "images.txt", "# h\n1 1 0 0 0 0.5\r0 0 1\r\n\n");
  expect_format_error([&] { read_colmap_text_model(dir.path()); }, dir / "images.txt", 2,
                      "expected IMAGE_ID");
}

// ---- Intrinsics JSON ----------------------------------------------------------------------------

TEST(IntrinsicsJson, RoundTripAndValidation) {
  test::TempDir dir;
  Intrinsics k{525.5, 524.25, 319.5, 239.75, 640, 480};
  write_intrinsics_json(dir / "k.json", k);
  Intrinsics b = read_intrinsics_json(dir / "k.json");
  EXPECT_EQ(b.fx, k.fx);
  EXPECT_EQ(b.fy, k.fy);
  EXPECT_EQ(b.cx, k.cx);
  EXPECT_EQ(b.cy, k.cy);
  EXPECT_EQ(b.width, k.width);
  EXPECT_EQ(b.height, k.height);

  std::vector<std::pair<std::string, std::string>> bad = {
      {R"({"fx": -1, "fy": 500, "cx": 320, "cy": 240, "width": 640, "height": 480})", "positive"},
      {R"({"fx": 500, "fy": 500, "cx": 900, "cy": 240, "width": 640, "height": 480})", "outside"},
      {R"({"fx": 500, "fy": 500, "cx": 320, "width": 640, "height": 480})", "\"cy\""},
      {R"({"fx": 500, "fy": 500, "cx": 320, "cy": 240, "width": 640.5, "height": 480})", "integer"},
      {R"({"fx": 1, "fy": 1, "cx": 320, "cy": 240, "width": 640, "height": 480})", "field of view"},
      {R"({"fx": 500, "fy": 5000, "cx": 320, "cy": 240, "width": 640, "height": 480})", "fy / fx"},
      {R"({"fx": "500", "fy": 500, "cx": 320, "cy": 240, "width": 640, "height": 480})", "number"},
      {R"({"fx": 500, )", "not valid JSON"},
  };
  for (size_t c = 0; c < bad.size(); ++c) {
    fs::path f = dir / ("bad" + std::to_string(c) + ".json");
    write_file(f, bad[c].first);
    try {
      read_intrinsics_json(f);
      ADD_FAILURE() << "accepted " << bad[c].first;
    } catch (const Error& e) {
      EXPECT_EQ(e.category(), ErrorCategory::format) << e.what();
      EXPECT_NE(std::string(e.what()).find(f.string()), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(bad[c].second), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(validate_intrinsics({0, 500, 320, 240, 640, 480}, "test"), Error);
  EXPECT_NO_THROW(validate_intrinsics({525, 525, 320, 240, 640, 480}, "test"));
  EXPECT_THROW(write_intrinsics_json(dir / "w.json", {500, 500, 320, 240, 0, 480}), Error);
  EXPECT_FALSE(fs::exists(dir / "w.json"));
}

TEST(TrajectoryIO, RunWithFrameStepWritesSourceTimesAndTakesItsPosesBack) {
  test::TempDir dir;
  const fs::path scene = dir / "scene";
  test::CommandResult r = test::run_cvd("scene --out " + test::shell_quoted(scene) +
                                        " --frames 7 --width 96 --height 64 --fps 30");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string common =
      " --first-frame 1 --frame-step 2 --epochs 0 --warmup 1 --width 0.0625 --depth-size 48"
      " --no-videos --no-ply --poses-format tum --intrinsics " +
      test::intrinsics_flag_value(scene / "intrinsics.json");
  const fs::path first = dir / "first", second = dir / "second";
  r = test::run_cvd("run " + test::shell_quoted(scene / "rgb") + " -o " +
                    test::shell_quoted(first) + " --poses " +
                    test::shell_quoted(scene / "poses.txt") + common);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::vector<TimedPose> given = read_tum_trajectory(scene / "poses.txt");
  const std::vector<TimedPose> written = read_tum_trajectory(first / "poses.txt");
  ASSERT_EQ(given.size(), 7u);
  ASSERT_EQ(written.size(), 3u);
  for (size_t k = 0; k < written.size(); ++k) {
    EXPECT_NEAR(written[k].timestamp, (1.0 + 2.0 * static_cast<double>(k)) / 30.0, 1e-9) << k;
    EXPECT_NEAR(written[k].timestamp, given[1 + 2 * k].timestamp, 1e-6) << k;  // %.6f
    EXPECT_LT((written[k].pose.t - given[1 + 2 * k].pose.t).norm(), 1e-9) << k;
  }
  r = test::run_cvd("run " + test::shell_quoted(scene / "rgb") + " -o " +
                    test::shell_quoted(second) + " --poses " +
                    test::shell_quoted(first / "poses.txt") + common);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::vector<TimedPose> again = read_tum_trajectory(second / "poses.txt");
  ASSERT_EQ(again.size(), written.size());
  for (size_t k = 0; k < again.size(); ++k) {
    EXPECT_NEAR(again[k].timestamp, written[k].timestamp, 1e-9) << k;
    EXPECT_LT((again[k].pose.t - written[k].pose.t).norm(), 1e-9) << k;
    EXPECT_LT((again[k].pose.R - written[k].pose.R).norm(), 1e-9) << k;
  }
}

// The widest angle between the rays that see a point: two cameras 1 apart see a point at depth 2
// on their bisector under 2 atan(0.5 / 2) = 28.07 deg; a third camera between them changes
// nothing; a point seen by one registered image (the other id is not in the model) is skipped.

}  // namespace
}  // namespace cvd
