// The public API (include/cvd) as an embedding application uses it: only <cvd/...> headers, linked
// through libcvd.so. Frames are a textured plane seen by a camera translating sideways, written by
// the test itself, with the exact poses as a TUM file.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include <cvd/cvd.h>

namespace {

namespace fs = std::filesystem;

// Value noise on a grid of `cell` world units: smooth, textured, deterministic.
double texture(double x, double y) {
  auto hash = [](int64_t i, int64_t j) {
    uint64_t h = uint64_t(i) * 0x9E3779B97F4A7C15ull ^ uint64_t(j) * 0xC2B2AE3D27D4EB4Full;
    h ^= h >> 31;
    h *= 0xBF58476D1CE4E5B9ull;
    h ^= h >> 29;
    return double(h % 1000) / 999.0;
  };
  double v = 0;
  for (double cell : {0.02, 0.06}) {
    const double gx = x / cell, gy = y / cell;
    const int64_t i = int64_t(std::floor(gx)), j = int64_t(std::floor(gy));
    const double fx = gx - i, fy = gy - j;
    v += (1 - fy) * ((1 - fx) * hash(i, j) + fx * hash(i + 1, j)) +
         fy * ((1 - fx) * hash(i, j + 1) + fx * hash(i + 1, j + 1));
  }
  return v / 2;
}

constexpr int kW = 128, kH = 96;
constexpr double kF = 100, kDepth = 2.0, kStep = 0.03;  // focal (px), plane depth, metres/frame

// Frame k of a camera at x = k * kStep looking at the plane z = kDepth.
cvd::Image plane_frame(int k) {
  cvd::Image img(kW, kH, 3);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const double X = (x - 0.5 * kW) * kDepth / kF + k * kStep, Y = (y - 0.5 * kH) * kDepth / kF;
      const auto v = uint8_t(std::clamp(255.0 * texture(X, Y), 0.0, 255.0));
      uint8_t* p = img.at(x, y);
      p[0] = v;
      p[1] = uint8_t(255 - v);
      p[2] = uint8_t(v / 2 + 64);
    }
  return img;
}

// Writes `n` frames and their TUM poses under `dir`; returns the options of a short run.
cvd::PipelineOptions short_run(const fs::path& dir, int n) {
  fs::create_directories(dir / "frames");
  std::ofstream poses(dir / "poses.txt");
  for (int k = 0; k < n; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%03d.png", k);
    cvd::write_image((dir / "frames" / name).string(), plane_frame(k));
    poses << k << " " << k * kStep << " 0 0 0 0 0 1\n";
  }
  cvd::PipelineOptions o;
  o.input = (dir / "frames").string();
  o.out = (dir / "out").string();
  o.poses_file = (dir / "poses.txt").string();
  o.intrinsics = cvd::CameraIntrinsics{kF, kF, 0.5 * kW, 0.5 * kH, kW, kH};
  o.depth_long_side = 64;
  o.flow_long_side = kW;
  o.epochs = 1;
  o.batch_pairs = 2;
  o.warmup_steps = 5;
  o.write_videos = false;
  o.write_point_cloud = false;
  return o;
}

fs::path fresh_dir(const std::string& name) {
  fs::path d = fs::temp_directory_path() / ("cvd_test_public_api_" + name);
  fs::remove_all(d);
  return d;
}

TEST(PublicApi, DepthModelInfersPositiveDepthAtTheAlignedNetworkSize) {
  cvd::DepthModelOptions opt;
  opt.long_side = 64;
  cvd::DepthModel model = cvd::DepthModel::create_default(opt);
  EXPECT_EQ(model.arch(), "mannequin");
  EXPECT_EQ(model.device(), cvd::Device::cpu);
  const cvd::DepthMap d = model.infer(plane_frame(0));
  // Long side = 64 (a multiple of the alignment), short side rounded to the alignment.
  EXPECT_EQ(d.width, 64);
  EXPECT_EQ(d.width % model.alignment(), 0);
  EXPECT_EQ(d.height % model.alignment(), 0);
  EXPECT_NEAR(d.height, 64.0 * kH / kW, model.alignment());
  ASSERT_EQ(d.depth.size(), size_t(d.width) * d.height);
  for (float v : d.depth) ASSERT_TRUE(std::isfinite(v) && v > 0) << v;
}

TEST(PublicApi, ErrorsCarryTheirCategory) {
  try {
    cvd::DepthModel::load("/nonexistent/dir/model.cvdw");
    FAIL() << "loading a missing file did not throw";
  } catch (const cvd::Error& e) {
    EXPECT_EQ(e.category(), cvd::ErrorCategory::io) << e.what();
    EXPECT_NE(std::string(e.what()).find("model.cvdw"), std::string::npos) << e.what();
    EXPECT_STREQ(cvd::error_category_name(e.category()), "io");
  }
  cvd::DepthModel model = cvd::DepthModel::create_default({});
  try {
    model.infer(cvd::Image{});
    FAIL() << "an empty image did not throw";
  } catch (const cvd::Error& e) {
    EXPECT_EQ(e.category(), cvd::ErrorCategory::invalid_argument) << e.what();
  }
  std::string reason;
  if (!cvd::device_available(cvd::Device::cuda, &reason)) {
    cvd::DepthModelOptions o;
    o.device = cvd::Device::cuda;
    try {
      cvd::DepthModel::create_default(o);
      FAIL() << "Device::cuda without CUDA did not throw";
    } catch (const cvd::Error& e) {
      EXPECT_EQ(e.category(), cvd::ErrorCategory::unsupported) << e.what();
    }
  }
}

TEST(PublicApi, DisFlowRecoversAKnownShiftWithItsConsistencyMask) {
  // b shows a's content 3 px further right: pixel (x, y) of a is at (x + 3, y) in b.
  const cvd::Image a = plane_frame(0);
  cvd::Image b = a;
  for (int y = 0; y < kH; ++y)
    for (int x = 3; x < kW; ++x)
      std::copy(a.pixels.begin() + (y * kW + x - 3) * 3, a.pixels.begin() + (y * kW + x - 2) * 3,
                b.at(x, y));
  cvd::FlowEstimator flow;
  const cvd::FlowPair r = flow.estimate(a, b);
  ASSERT_EQ(r.forward.width, kW);
  ASSERT_EQ(r.forward.height, kH);
  std::vector<float> u;
  for (size_t i = 0; i < r.forward.valid.size(); ++i)
    if (r.forward.valid[i]) u.push_back(r.forward.uv[2 * i]);
  EXPECT_GT(r.forward.valid_fraction, 0.5);
  ASSERT_FALSE(u.empty());
  std::nth_element(u.begin(), u.begin() + u.size() / 2, u.end());
  EXPECT_NEAR(u[u.size() / 2], 3.0, 0.5);  // median over consistent pixels, 0.5 px tolerance
}

TEST(PublicApi, PipelineReportsProgressAndReturnsResultsInMemory) {
  const fs::path dir = fresh_dir("run");
  cvd::PipelineOptions o = short_run(dir, 4);
  std::vector<cvd::PipelineProgress> reports;
  o.progress = [&](const cvd::PipelineProgress& p) { reports.push_back(p); };
  const cvd::PipelineResult r = cvd::Pipeline(o).run();

  ASSERT_EQ(r.frame_names.size(), 4u);
  ASSERT_EQ(r.cameras.size(), 4u);
  ASSERT_EQ(r.depths.size(), 4u);
  for (const cvd::DepthMap& d : r.depths) {
    EXPECT_EQ(std::max(d.width, d.height), 64);
    for (float v : d.depth) ASSERT_TRUE(std::isfinite(v) && v > 0);
  }
  // Poses come from the file: a pure translation along x, equal steps (up to the output scale).
  const double step = r.cameras[1].camera_to_world[3] - r.cameras[0].camera_to_world[3];
  EXPECT_GT(std::abs(step), 0);
  for (int k = 0; k < 4; ++k) {
    EXPECT_NEAR(r.cameras[k].camera_to_world[3], k * step, 1e-6 * std::abs(step) + 1e-9);
    EXPECT_NEAR(r.cameras[k].camera_to_world[0], 1.0, 1e-9);  // identity rotation
  }
  EXPECT_TRUE(fs::exists(dir / "out" / "run.json"));

  // Progress: every stage reports counts that never decrease and never exceed a known total.
  ASSERT_FALSE(reports.empty());
  std::map<std::string, int> last;
  bool some_stage_completed = false;
  for (const cvd::PipelineProgress& p : reports) {
    EXPECT_FALSE(p.stage.empty());
    if (p.total > 0) {  // total 0 = not known yet
      EXPECT_LE(p.done, p.total) << p.stage;
    }
    auto it = last.find(p.stage);
    if (it != last.end()) {
      EXPECT_GE(p.done, it->second) << p.stage;
    }
    last[p.stage] = p.done;
    some_stage_completed |= p.total > 0 && p.done == p.total;
  }
  EXPECT_TRUE(some_stage_completed);
  EXPECT_TRUE(last.count("training")) << "no training progress reported";
  fs::remove_all(dir);
}

TEST(PublicApi, PipelineRejectsUnknownSettingsBeforeCreatingAnything) {
  // The CLI checks these values; library callers reach run_pipeline directly.
  const std::vector<std::function<void(cvd::PipelineOptions&)>> bad = {
      [](cvd::PipelineOptions& o) { o.refine_poses = "yes"; },
      [](cvd::PipelineOptions& o) { o.sparse_points = "sift"; },
      [](cvd::PipelineOptions& o) { o.given_poses = "refined"; },
      [](cvd::PipelineOptions& o) { o.warmup_scale = "scene"; },
      [](cvd::PipelineOptions& o) { o.poses_source = "slam"; },
      [](cvd::PipelineOptions& o) { o.colmap_keyframes = "1"; },
      [](cvd::PipelineOptions& o) { o.steps = -1; },
      [](cvd::PipelineOptions& o) {
        o.depth_formats = {"pfm", "tiff"};
      }};
  for (size_t k = 0; k < bad.size(); ++k) {
    const fs::path dir = fresh_dir("bad_setting_" + std::to_string(k));
    cvd::PipelineOptions o = short_run(dir, 4);
    o.out = (dir / "never_created").string();
    bad[k](o);
    try {
      cvd::Pipeline(o).run();
      ADD_FAILURE() << "setting " << k << " was accepted";
    } catch (const cvd::Error& e) {
      EXPECT_EQ(e.category(), cvd::ErrorCategory::invalid_argument) << e.what();
    }
    EXPECT_FALSE(fs::exists(dir / "never_created")) << "setting " << k;
  }
}

TEST(PublicApi, QualityPresetsSetTheCostKnobsAndDefaultIsTheDefaults) {
  const cvd::PipelineOptions defaults;
  cvd::PipelineOptions o;
  o.seed = 7;
  cvd::apply_quality_preset(o, "default");
  EXPECT_EQ(o.depth_long_side, defaults.depth_long_side);
  EXPECT_EQ(o.width, defaults.width);
  EXPECT_EQ(o.epochs, defaults.epochs);
  EXPECT_EQ(o.warmup_steps, defaults.warmup_steps);
  EXPECT_EQ(o.seed, 7u) << "a preset touches only its four fields";
  cvd::PipelineOptions fast, best;
  cvd::apply_quality_preset(fast, "fast");
  cvd::apply_quality_preset(best, "best");
  // Each step up costs no less in any knob it sets, and more in all together.
  EXPECT_LT(fast.depth_long_side, o.depth_long_side);
  EXPECT_LE(o.depth_long_side, best.depth_long_side);
  EXPECT_LE(fast.width, o.width);
  EXPECT_LE(o.width, best.width);
  EXPECT_LT(fast.epochs, o.epochs);
  EXPECT_LE(o.epochs, best.epochs);
  EXPECT_LT(o.epochs * o.depth_long_side * o.depth_long_side * o.width * o.width,
            best.epochs * best.depth_long_side * best.depth_long_side * best.width * best.width);
  try {
    cvd::apply_quality_preset(o, "ultra");
    ADD_FAILURE() << "an unknown preset was accepted";
  } catch (const cvd::Error& e) {
    EXPECT_EQ(e.category(), cvd::ErrorCategory::invalid_argument);
    EXPECT_NE(std::string(e.what()).find("ultra"), std::string::npos) << e.what();
  }
}

TEST(PublicApi, PipelineStopsWithCancelledWhenTheFlagIsSet) {
  const fs::path dir = fresh_dir("cancel");
  cvd::PipelineOptions o = short_run(dir, 4);
  std::atomic<bool> cancel{false};
  int reports_after_cancel = 0;
  o.cancel = &cancel;
  o.progress = [&](const cvd::PipelineProgress&) {
    if (cancel) ++reports_after_cancel;
    cancel = true;  // ask to stop at the first report
  };
  try {
    cvd::Pipeline(o).run();
    FAIL() << "the run finished although cancellation was requested";
  } catch (const cvd::Error& e) {
    EXPECT_EQ(e.category(), cvd::ErrorCategory::cancelled) << e.what();
  }
  EXPECT_LE(reports_after_cancel, 1);  // stops at the next check, not at the end
  fs::remove_all(dir);
}

}  // namespace
