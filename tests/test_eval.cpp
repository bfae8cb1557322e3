// Evaluation's readers and runs: the GT and run readers (including their rejection of malformed
// files), `cvd eval` end to end, and the HTML report rendered by headless Chromium. The metrics
// themselves: test_eval_metrics.cpp.
#include <gtest/gtest.h>

#include <algorithm>
#include <set>

#include <Eigen/Geometry>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

#include "engine/error.h"
#include "pipeline/eval/eval_consistency.h"
#include "pipeline/eval/eval_depth_metrics.h"
#include "pipeline/eval/eval_pose_metrics.h"
#include "pipeline/eval/eval_readers.h"
#include "pipeline/eval/eval_report.h"
#include "pipeline/eval/eval_run.h"
#include "pipeline/io/image_io.h"
#include "pipeline/io/pfm_io.h"
#include "pipeline/io/sparse_depth_io.h"
#include "pipeline/io/trajectory_io.h"
#include "tests/eval_plane_scene.h"
#include "tests/test_support.h"

namespace fs = std::filesystem;
using namespace cvd;
using cvd::test::PlaneScene;

namespace {

void write_text(const fs::path& p, const std::string& s) {
  fs::create_directories(p.parent_path());
  std::ofstream(p) << s;
}

// Expects `f` to throw cvd::Error whose message contains every string of `needles`.
template <class F>
void expect_error_naming(F&& f, std::initializer_list<std::string> needles) {
  try {
    f();
    ADD_FAILURE() << "expected a cvd::Error";
  } catch (const Error& e) {
    for (auto& n : needles)
      EXPECT_NE(std::string(e.what()).find(n), std::string::npos)
          << "message '" << e.what() << "' lacks '" << n << "'";
  }
}

}  // namespace

// ---- readers ------------------------------------------------------------------------------------

// Writes a demo-layout GT folder and a matching cvd run (depth scaled by 1/s, poses by S^-1).
static void write_scene(const PlaneScene& sc, const fs::path& gt, const fs::path& run, double s) {
  fs::create_directories(gt / "rgb");
  fs::create_directories(gt / "depth");
  fs::create_directories(run / "depth");
  std::vector<TimedPose> gp, rp;
  for (size_t k = 0; k < sc.grey.size(); ++k) {
    std::string name = fmt::format("frame_{:06d}", k);
    cv::Mat bgr;
    cv::cvtColor(sc.grey[k], bgr, cv::COLOR_GRAY2BGR);
    cv::imwrite((gt / "rgb" / (name + ".png")).string(), bgr);
    write_pfm(gt / "depth" / (name + ".pfm"), sc.depth[k]);
    write_pfm(run / "depth" / (name + ".pfm"), cv::Mat(sc.depth[k] / s));
    gp.push_back({k / 30.0, sc.poses[k]});
    Pose p = sc.poses[k];
    p.t /= s;
    rp.push_back({k / 30.0, p});
  }
  write_tum_trajectory(gt / "poses.txt", gp);
  write_tum_trajectory(run / "poses.txt", rp);
  write_intrinsics_json(gt / "intrinsics.json", sc.K);
  write_intrinsics_json(run / "intrinsics.json", sc.K);
  write_text(run / "run.json", "{\"version\": \"test\"}");
}

TEST(EvalReaders, DemoLayoutAndRunAreMatchedByName) {
  test::TempDir tmp;
  PlaneScene sc(4);
  write_scene(sc, tmp / "gt", tmp / "run", 2.0);
  EXPECT_EQ(detect_gt_format(tmp / "gt"), GtFormat::demo);
  EvalSequence gt = read_gt_sequence(tmp / "gt", GtFormat::auto_detect);
  EvalSequence run = read_cvd_run(tmp / "run");
  ASSERT_EQ(gt.frames.size(), 4u);
  EXPECT_TRUE(gt.has_depth() && gt.has_poses() && gt.has_images());
  EXPECT_TRUE(run.has_depth() && run.has_poses());
  EXPECT_EQ(gt.frames[2].name, "frame_000002");
  ASSERT_TRUE(run.intrinsics.has_value());
  EXPECT_DOUBLE_EQ(run.intrinsics->fx, 100);
  // Drop frame 1 from the run: matching is by name, not by index.
  fs::remove(tmp / "run" / "depth" / "frame_000001.pfm");
  write_text(tmp / "run" / "run.json",
             R"({"frames": [{"name": "frame_000000"}, {"name": "frame_000002"},
                            {"name": "frame_000003"}]})");
  EvalSequence gt2 = gt;
  gt2.frames[1].pose.reset();
  std::vector<TimedPose> rp = read_tum_trajectory(tmp / "run" / "poses.txt");
  rp.erase(rp.begin() + 1);
  write_tum_trajectory(tmp / "run" / "poses.txt", rp);
  EvalSequence run2 = read_cvd_run(tmp / "run");
  auto m = match_frames(run2, gt);
  ASSERT_EQ(m.size(), 3u);
  EXPECT_EQ(m[1].gt, 2u);
  EXPECT_EQ(m[1].pred, 1u);
  EXPECT_EQ(run2.frames[1].name, "frame_000002");
  EXPECT_NEAR(run2.frames[1].pose->t.x(), sc.poses[2].t.x() / 2, 1e-6);
  cv::Mat d = load_eval_depth(run2.frames[1]);
  EXPECT_FLOAT_EQ(d.at<float>(5, 5), 1.0f);
}

TEST(EvalReaders, MatchesByTimestampWhenNamesDiffer) {
  EvalSequence pred, gt;
  for (int i = 0; i < 3; ++i) {
    pred.frames.push_back({fmt::format("p{}", i), i * 0.1 + 0.005, {}, 1, {}, std::nullopt});
    gt.frames.push_back({fmt::format("g{}", i), i * 0.1, {}, 1, {}, std::nullopt});
  }
  gt.frames.push_back({"g3", 5.0, {}, 1, {}, std::nullopt});  // no prediction within 20 ms
  auto m = match_frames(pred, gt);
  ASSERT_EQ(m.size(), 3u);
  EXPECT_EQ(m[2].pred, 2u);
  EXPECT_EQ(m[2].gt, 2u);
}

TEST(EvalReaders, RejectMalformedFilesNamingThem) {
  test::TempDir tmp;
  PlaneScene sc(3);
  write_scene(sc, tmp / "gt", tmp / "run", 1.0);
  // A malformed pose line.
  write_text(tmp / "run" / "poses.txt", "0 1 2 3 0 0 0 1\n0.1 1 2 oops\n0.2 0 0 0 0 0 0 1\n");
  expect_error_naming([&] { read_cvd_run(tmp / "run"); }, {"poses.txt"});
  // Pose count does not match the frames.
  write_text(tmp / "run" / "poses.txt", "0 1 2 3 0 0 0 1\n");
  expect_error_naming([&] { read_cvd_run(tmp / "run"); }, {"poses.txt", "1 poses for 3 frames"});
  fs::remove(tmp / "run" / "poses.txt");
  // run.json that is not JSON.
  write_text(tmp / "run" / "run.json", "{ not json");
  expect_error_naming([&] { read_cvd_run(tmp / "run"); }, {"run.json", "JSON"});
  write_text(tmp / "run" / "run.json", "{}");
  // A truncated PFM.
  write_text(tmp / "run" / "depth" / "frame_000000.pfm", "Pf\n160 120\n-1\nabc");
  EvalSequence run = read_cvd_run(tmp / "run");
  expect_error_naming([&] { load_eval_depth(run.frames[0]); }, {"frame_000000.pfm"});
  // No depth at all.
  expect_error_naming([&] { read_cvd_run(tmp / "gt" / "rgb"); }, {"depth"});
  // TUM: bad timestamp in associations.txt, 8-bit depth PNG, bad intrinsics text.
  fs::path tum = tmp / "tum";
  write_text(tum / "associations.txt", "# comment\n0.0 rgb/a.png x depth/a.png\n");
  expect_error_naming([&] { read_gt_sequence(tum, GtFormat::auto_detect); },
                      {"associations.txt:2", "timestamp"});
  write_text(tum / "associations.txt", "0.0 rgb/a.png 0.0 depth/a.png\n");
  fs::create_directories(tum / "depth");
  cv::imwrite((tum / "depth" / "a.png").string(), cv::Mat(4, 4, CV_8U, cv::Scalar(7)));
  EvalSequence ts = read_gt_sequence(tum, GtFormat::tum);
  expect_error_naming([&] { load_eval_depth(ts.frames[0]); }, {"a.png", "16-bit"});
  write_text(tum / "intrinsics_rgb.txt", "# fx fy cx cy w h\n525 525 320\n");
  expect_error_naming([&] { read_gt_sequence(tum, GtFormat::tum); }, {"intrinsics_rgb.txt"});
  EXPECT_THROW(parse_gt_format("kitti"), Error);
}

TEST(EvalReaders, SevenScenesSharedData) {
  CVD_REQUIRE_SHARED_DATA(dir, "7scenes_redkitchen_f000000-000149");
  EXPECT_EQ(detect_gt_format(dir), GtFormat::tum);
  EvalSequence gt = read_gt_sequence(dir, GtFormat::auto_detect);
  ASSERT_EQ(gt.frames.size(), 150u);
  EXPECT_TRUE(gt.has_poses() && gt.has_depth() && gt.has_images());
  EXPECT_EQ(gt.frames[123].name, "frame-000123.color");
  EXPECT_NEAR(*gt.frames[123].timestamp, 4.1, 1e-6);
  ASSERT_TRUE(gt.intrinsics.has_value());
  EXPECT_DOUBLE_EQ(gt.intrinsics->fx, 525.0);
  // First pose line of groundtruth_rgb.txt: t = (-0.3165422, 0.0093614, 0.3024787).
  EXPECT_NEAR(gt.frames[0].pose->t.x(), -0.3165422, 1e-7);
  cv::Mat d = load_eval_depth(gt.frames[0]);
  ASSERT_EQ(d.size(), cv::Size(640, 480));
  double lo, hi;
  cv::minMaxLoc(d, &lo, &hi, nullptr, nullptr, d > 0);
  EXPECT_GT(lo, 0.2);  // metres: a kitchen seen by a Kinect v1
  EXPECT_LT(hi, 8.0);
  EXPECT_GT(cv::countNonZero(d) / double(d.total()), 0.5);  // README: ~72% valid
}

// ---- end to end and report ----------------------------------------------------------------------

TEST(EvalRun, ScaledRunAgainstDemoGt) {
  test::TempDir tmp;
  PlaneScene sc(8);
  write_scene(sc, tmp / "gt", tmp / "run", 2.0);  // the run is the GT at half scale
  EvalRunOptions o;
  o.pred_dir = tmp / "run";
  o.gt_dir = tmp / "gt";
  EvalOutcome r = evaluate_run(o);
  const auto& m = r.metrics;
  EXPECT_EQ(m["frames"]["matched"], 8);
  EXPECT_NEAR(m["depth"]["none"]["depth"]["abs_rel"].get<double>(), 0.5, 1e-6);
  EXPECT_NEAR(m["depth"]["median_frame"]["depth"]["abs_rel"].get<double>(), 0.0, 1e-6);
  EXPECT_NEAR(m["depth"]["median_video"]["disparity"]["abs_rel"].get<double>(), 0.0, 1e-6);
  EXPECT_NEAR(m["pose"]["ate_rmse"].get<double>(), 0.0, 1e-6);
  EXPECT_NEAR(m["pose"]["sim3"]["scale"].get<double>(), 2.0, 1e-6);
  // The split by texture from the frames (the plane is textured everywhere; both regions exact).
  const auto& t = m["depth_by_texture"];
  EXPECT_NEAR(t["low_texture"]["share"].get<double>() + t["textured"]["share"].get<double>(), 1.0,
              1e-12);
  EXPECT_GT(t["textured"]["share"].get<double>(), 0.5);
  EXPECT_NEAR(t["textured"]["abs_rel"].get<double>(), 0.0, 1e-6);
  ASSERT_FALSE(m["consistency"].contains("skipped")) << m["consistency"].dump();
  EXPECT_LT(m["consistency"]["flow_reprojection_px"].get<double>(), 0.5);  // DIS on exact motion
  EXPECT_LT(m["consistency"]["instability"].get<double>(), 0.005);         // run units (1 m plane)
  EXPECT_EQ(r.thumbnails.size(), 8u);  // 4 frames x (GT, prediction)
  write_eval_outputs(tmp / "out", r);
  std::ifstream in(tmp / "out" / "metrics.json");
  nlohmann::json back = nlohmann::json::parse(in);
  EXPECT_EQ(back["depth"]["lstsq_frame"]["depth"]["frames"], 8);
  // No GT: only the consistency section.
  EvalRunOptions ng;
  ng.pred_dir = tmp / "run";
  ng.frames_dir = tmp / "gt" / "rgb";
  EvalOutcome r2 = evaluate_run(ng);
  EXPECT_FALSE(r2.metrics.contains("depth"));
  EXPECT_FALSE(r2.metrics.contains("pose"));
  EXPECT_TRUE(r2.metrics["consistency"].contains("instability"));
}

// The run's sparse points: read from sparse_depth.csv.gz (what runs write), or from the
// uncompressed sparse_depth.csv of older runs when that is all there is.
TEST(EvalRun, SparsePointsCompressedOrFromOlderRuns) {
  test::TempDir tmp;
  PlaneScene sc(4);
  write_scene(sc, tmp / "gt", tmp / "run", 2.0);
  // Points on the run's own depth (half the GT's): exact up to the one scale.
  std::map<std::string, SparseDepthFrame> pts;
  for (size_t k = 0; k < sc.depth.size(); ++k) {
    SparseDepthFrame& f = pts[fmt::format("frame_{:06d}", k)];
    f.width = sc.depth[k].cols, f.height = sc.depth[k].rows;
    for (int y = 2; y < f.height; y += 7)
      for (int x = 3; x < f.width; x += 9)
        f.points.push_back({double(x), double(y), sc.depth[k].at<float>(y, x) / 2.0});
  }
  // An older file with a wrong point in every frame: used only when it is the only file.
  std::map<std::string, SparseDepthFrame> old = pts;
  for (auto& [name, f] : old) f.points.front().z *= 3;
  write_sparse_depth_csv(tmp / "run" / kSparseDepthFileUncompressed, old);
  EvalRunOptions o;
  o.pred_dir = tmp / "run";
  o.gt_dir = tmp / "gt";
  const EvalOutcome from_old = evaluate_run(o);
  ASSERT_TRUE(from_old.metrics.contains("sparse"));
  EXPECT_GT(from_old.metrics["sparse"]["abs_rel"].get<double>(), 1e-3);
  write_sparse_depth_csv(tmp / "run" / kSparseDepthFile, pts);
  const EvalOutcome r = evaluate_run(o);
  ASSERT_TRUE(r.metrics.contains("sparse"));
  EXPECT_EQ(r.metrics["sparse"]["frames"], 4);
  EXPECT_NEAR(r.metrics["sparse"]["abs_rel"].get<double>(), 0.0, 1e-6);
  EXPECT_NEAR(r.metrics["sparse"]["abs_rel_video"].get<double>(), 0.0, 1e-6);
}

TEST(EvalRun, SevenScenesGtAtHalfScale) {
  // A run made from the real GT itself at half scale (holes filled with 1 m): exercises the TUM
  // path end to end (names with dots, timestamps, 16-bit PNG depth, 2-D/3-D on real images).
  CVD_REQUIRE_SHARED_DATA(dir, "7scenes_redkitchen_f000000-000149");
  test::TempDir tmp;
  EvalSequence gt = read_gt_sequence(dir, GtFormat::tum);
  const int n = 8;
  std::vector<TimedPose> poses;
  fs::create_directories(tmp / "run" / "depth");
  for (int i = 0; i < n; ++i) {
    cv::Mat d = load_eval_depth(gt.frames[i]) * 0.5;
    d.setTo(1.0f, d <= 0);
    write_pfm(tmp / "run" / "depth" / (gt.frames[i].name + ".pfm"), d);
    Pose p = *gt.frames[i].pose;
    p.t *= 0.5;
    poses.push_back({*gt.frames[i].timestamp, p});
  }
  write_tum_trajectory(tmp / "run" / "poses.txt", poses);
  write_intrinsics_json(tmp / "run" / "intrinsics.json", *gt.intrinsics);
  EvalRunOptions o;
  o.pred_dir = tmp / "run";
  o.gt_dir = dir;
  o.depth.max_depth = 10;
  EvalOutcome r = evaluate_run(o);
  const auto& m = r.metrics;
  EXPECT_EQ(m["frames"]["matched"], n);
  EXPECT_NEAR(m["depth"]["none"]["depth"]["abs_rel"].get<double>(), 0.5, 1e-6);
  EXPECT_NEAR(m["depth"]["median_frame"]["depth"]["abs_rel"].get<double>(), 0.0, 1e-6);
  EXPECT_NEAR(m["depth"]["median_video"]["depth"]["delta1"].get<double>(), 1.0, 1e-9);
  EXPECT_NEAR(m["pose"]["ate_rmse"].get<double>(), 0.0, 1e-6);
  EXPECT_NEAR(m["pose"]["sim3"]["scale"].get<double>(), 2.0, 1e-6);
  ASSERT_TRUE(m["consistency"].contains("instability")) << m["consistency"].dump();
  EXPECT_GT(m["consistency"]["tracks"].get<int>(), 100);
  // Measured depth + KinectFusion poses are consistent to ~1 cm (README: 4-8 mm median |dz|),
  // i.e. ~5 mm at half scale; allow 3 cm. Reprojection vs DIS flow: a few pixels at most.
  EXPECT_LT(m["consistency"]["instability"].get<double>(), 0.03);
  EXPECT_LT(m["consistency"]["drift"].get<double>(), 0.06);
  EXPECT_LT(m["consistency"]["flow_reprojection_px"].get<double>(), 3.0);
}

TEST(EvalRun, CliWritesOutputsAndRejectsBadInput) {
  test::TempDir tmp;
  PlaneScene sc(5);
  write_scene(sc, tmp / "gt", tmp / "run", 1.0);
  auto ok = test::run_cvd(fmt::format("eval --pred {} --gt {} --out {} --max-depth 10",
                                      (tmp / "run").string(), (tmp / "gt").string(),
                                      (tmp / "out").string()));
  ASSERT_EQ(ok.exit_code, 0) << ok.output;
  EXPECT_TRUE(fs::exists(tmp / "out" / "metrics.json"));
  EXPECT_TRUE(fs::exists(tmp / "out" / "report.html"));
  for (auto& e : fs::directory_iterator(tmp / "out"))  // atomic writes leave no temporaries
    EXPECT_EQ(e.path().filename().string()[0] != '.', true) << e.path();
  write_text(tmp / "run" / "poses.txt", "garbage\n");
  auto bad = test::run_cvd(fmt::format("eval --pred {}", (tmp / "run").string()));
  EXPECT_EQ(bad.exit_code, 3) << bad.output;  // kExitBadInput
  EXPECT_NE(bad.output.find("poses.txt"), std::string::npos) << bad.output;
}

TEST(EvalReport, Base64AndSvg) {
  EXPECT_EQ(base64_encode({'M', 'a', 'n'}), "TWFu");
  EXPECT_EQ(base64_encode({'M', 'a'}), "TWE=");
  EXPECT_EQ(base64_encode({'M'}), "TQ==");
  std::string svg = svg_line_plot("t<1>", "x", "y", {{"a", {0, 1, 2}, {1, 4, NAN}}});
  EXPECT_NE(svg.find("<svg"), std::string::npos);
  EXPECT_NE(svg.find("t&lt;1&gt;"), std::string::npos);  // escaped title
  EXPECT_NE(svg.find("<polyline"), std::string::npos);
}

TEST(EvalReport, RendersInHeadlessChromium) {
  if (std::system("command -v chromium > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "chromium not installed (scripts/install-deps.sh installs it)";
  test::TempDir tmp;
  PlaneScene sc(6);
  write_scene(sc, tmp / "gt", tmp / "run", 2.0);
  EvalRunOptions o;
  o.pred_dir = tmp / "run";
  o.gt_dir = tmp / "gt";
  write_eval_outputs(tmp / "out", evaluate_run(o));
  std::string cmd = fmt::format(
      "chromium --headless --no-sandbox --disable-gpu --disable-background-networking "
      "--user-data-dir={} --dump-dom file://{}",
      (tmp / "profile").string(), (tmp / "out" / "report.html").string());
  auto r = test::run_command(cmd);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // The DOM as Chromium parsed it: the SVG plots, the tables and the inline thumbnails.
  auto count = [&](const std::string& s) {
    size_t n = 0;
    for (size_t p = r.output.find(s); p != std::string::npos; p = r.output.find(s, p + 1)) ++n;
    return n;
  };
  EXPECT_GE(count("<svg"), 7u);  // 2x2 depth plots, trajectory, ATE, flow pairs
  EXPECT_GE(count("<polyline"), 7u);
  EXPECT_GE(count("data:image/png;base64,"), 9u);  // 8 thumbnails and their colour bar
  EXPECT_NE(r.output.find("Sorted per-pixel AbsRel"), std::string::npos);
  EXPECT_NE(r.output.find("Trajectory, top view"), std::string::npos);
  // The plots hold the aligned rows only (the unaligned ones set the axis and flattened them).
  EXPECT_EQ(r.output.find(">none</text>"), std::string::npos);
  EXPECT_NE(r.output.find(">median_frame</text>"), std::string::npos);
  EXPECT_NE(r.output.find("depth colour bar"), std::string::npos);
  EXPECT_NE(r.output.find("Depth by texture"), std::string::npos);

  // And as a person sees it: a screenshot with the plots' lines and the turbo thumbnails. The
  // screenshot waits for the page to settle (its inline images decoded and painted): without
  // that, a CI run on a busy machine caught it before the thumbnails were drawn (89 colours,
  // 0.1% saturated).
  const fs::path shot = tmp / "report.png";
  auto s = test::run_command(fmt::format(
      "chromium --headless --no-sandbox --disable-gpu --disable-background-networking "
      "--hide-scrollbars --run-all-compositor-stages-before-draw --virtual-time-budget=10000 "
      "--user-data-dir={} --window-size=1200,2400 --screenshot={} file://{}",
      (tmp / "profile2").string(), shot.string(), (tmp / "out" / "report.html").string()));
  ASSERT_EQ(s.exit_code, 0) << s.output;
  const cv::Mat img = cv::imread(shot.string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(img.empty()) << s.output;
  // Distinct colours: a blank or text-only page has a few dozen greys at most; lines, legends
  // and colour-mapped thumbnails give more than a hundred (measured: 191). Saturated pixels
  // (the turbo thumbnails and their colour bar) cover over 1% of the page (measured: 2.0%).
  std::set<int> colours;
  size_t saturated = 0, sampled = 0;
  for (int y = 0; y < img.rows; y += 2)
    for (int x = 0; x < img.cols; x += 2) {
      const cv::Vec3b p = img.at<cv::Vec3b>(y, x);
      colours.insert((p[0] >> 3) << 10 | (p[1] >> 3) << 5 | (p[2] >> 3));
      const int hi = std::max({p[0], p[1], p[2]}), lo = std::min({p[0], p[1], p[2]});
      saturated += hi - lo > 100;
      ++sampled;
    }
  EXPECT_GT(colours.size(), 100u);
  EXPECT_GT(double(saturated) / double(sampled), 0.01);
  std::printf("[report screenshot] %zu colours, %.1f%% saturated pixels\n", colours.size(),
              100.0 * double(saturated) / double(sampled));
}
