// Pose stage building blocks: trajectory / COLMAP / intrinsics file IO, pair sampling and scale
// calibration. (The COLMAP driver itself is exercised in test_colmap.cpp.)
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
