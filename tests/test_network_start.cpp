// The default network's start (pipeline/training/network_start.h): a flat plane at the median
// sparse depth, a warm-up kept only as far as it beats that plane on held-out points, and a
// fallback level with a warning when there are no sparse points.
#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>

#include "engine/autograd.h"
#include "engine/ops.h"
#include "engine/random.h"
#include "models/depth_net_architectures.h"
#include "pipeline/training/network_start.h"
#include "scene/synthetic_scene.h"

namespace cvd {
namespace {

constexpr int kFrames = 8, kW = 96, kH = 64;

struct Fixture {
  SyntheticScene scene;
  std::vector<Tensor> images;  // [3, kH, kW] in [0, 1]
  std::function<Tensor(int)> load = [this](int k) { return images[size_t(k)]; };

  Fixture() {
    SyntheticSceneOptions so;
    so.frames = kFrames;
    so.width = kW;
    so.height = kH;
    so.supersampling = 1;
    scene = render_synthetic_scene(so);
    for (const SyntheticFrame& f : scene.frames) {
      cv::Mat rgb;
      cv::cvtColor(f.rgb, rgb, cv::COLOR_BGR2RGB);
      Tensor t = Tensor::empty({3, kH, kW});
      float* p = t.data<float>();
      for (int c = 0; c < 3; ++c)
        for (int y = 0; y < kH; ++y)
          for (int x = 0; x < kW; ++x)
            p[(c * kH + y) * kW + x] = rgb.at<cv::Vec3b>(y, x)[c] / 255.f;
      images.push_back(t);
    }
  }

  // `per_frame` points per frame at pseudo-random pixels: the true depth, or (noise) a depth
  // unrelated to the image.
  std::vector<SparseDepth> points(int per_frame, bool noise) const {
    Generator g(7);
    std::vector<SparseDepth> s(kFrames);
    for (int k = 0; k < kFrames; ++k)
      for (int q = 0; q < per_frame; ++q) {
        const int x = static_cast<int>(g.randint(0, kW)), y = static_cast<int>(g.randint(0, kH));
        const double z =
            noise ? 0.5 + 4.0 * g.uniform() : scene.frames[size_t(k)].depth.at<float>(y, x);
        s[size_t(k)].u.push_back(x);
        s[size_t(k)].v.push_back(y);
        s[size_t(k)].z.push_back(z);
      }
    return s;
  }
};

std::unique_ptr<DepthNet> tiny_net() {
  Generator gen(3);
  return depth_net_architecture("mannequin").create(1.0 / 16, gen);
}

Tensor depth_of(DepthNet& net, const Tensor& image) {
  NoGradGuard ng;
  net.eval();
  return net.depth(image.unsqueeze(0));
}

// The warm-up error on the held-out frames (every 4th frame with points), recomputed here.
double held_out_error(DepthNet& net, const Fixture& f, const std::vector<SparseDepth>& s) {
  double sum = 0;
  int frames = 0;
  for (int k = 3; k < kFrames; k += 4) {
    Tensor d = depth_of(net, f.images[size_t(k)]);
    const float* p = d.data<float>();
    double e = 0;
    for (size_t q = 0; q < s[size_t(k)].z.size(); ++q) {
      const int x = static_cast<int>(s[size_t(k)].u[q]), y = static_cast<int>(s[size_t(k)].v[q]);
      e += std::abs(std::log(p[y * kW + x]) - std::log(s[size_t(k)].z[q]));
    }
    sum += e / static_cast<double>(s[size_t(k)].z.size());
    ++frames;
  }
  return sum / frames;
}

TEST(NetworkStart, WithoutWarmUpTheFirstPredictionIsAFlatPlaneAtTheMedianSparseDepth) {
  Fixture f;
  auto net = tiny_net();
  const std::vector<SparseDepth> s = f.points(40, false);
  std::vector<double> all;
  for (const SparseDepth& d : s) all.insert(all.end(), d.z.begin(), d.z.end());
  std::nth_element(all.begin(), all.begin() + all.size() / 2, all.end());
  NetworkStartOptions o;
  o.warmup_steps = 0;
  const nlohmann::json info = start_default_network(*net, f.load, s, o);
  EXPECT_EQ(info["start"], "flat plane");
  for (int k : {0, 5}) {
    Tensor d = depth_of(*net, f.images[size_t(k)]);
    const float* p = d.data<float>();
    for (int64_t q = 0; q < d.numel(); ++q)
      ASSERT_NEAR(p[q], all[all.size() / 2], 1e-5 * all[all.size() / 2]) << "pixel " << q;
  }
}

TEST(NetworkStart, TheKeptStateIsTheBestOnHeldOutFramesAndNeverWorseThanThePlane) {
  Fixture f;
  for (bool noise : {false, true}) {
    auto net = tiny_net();
    const std::vector<SparseDepth> s = f.points(60, noise);
    NetworkStartOptions o;
    o.warmup_steps = 40;
    o.lr = 1e-3;
    const nlohmann::json info = start_default_network(*net, f.load, s, o);
    const double flat = info["held_out_error_flat_plane"], kept = info["held_out_error_kept"];
    EXPECT_LE(kept, flat) << "noise " << noise;
    // The network left behind is the state that was scored (restored, not the last step's).
    EXPECT_NEAR(held_out_error(*net, f, s), kept, 2e-3 * std::max(1.0, kept)) << "noise " << noise;
    if (!noise) {
      // True depths: the warm-up learns something that holds on frames it never saw.
      EXPECT_GT(info["warmup_kept_step"].get<int>(), 0);
      EXPECT_LT(kept, flat);
    }
  }
}

TEST(NetworkStart, NoSparsePointsGivesTheFallbackPlaneAndAWarning) {
  Fixture f;
  auto net = tiny_net();
  NetworkStartOptions o;
  o.fallback_depth = 2.5;
  std::vector<std::string> warnings;
  const nlohmann::json info =
      start_default_network(*net, f.load, std::vector<SparseDepth>(kFrames), o, &warnings);
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("no sparse 3-D points"), std::string::npos) << warnings[0];
  EXPECT_EQ(info["initial_depth_source"], "fallback");
  Tensor d = depth_of(*net, f.images[0]);
  EXPECT_NEAR(d.data<float>()[0], 2.5, 1e-5);
  EXPECT_NEAR(d.data<float>()[d.numel() - 1], 2.5, 1e-5);
}

// On a long clip the held-out frames are capped at 64 (every n-th frame with points), so that each
// check costs what it does on a clip of 256 frames; shorter clips keep every 4th frame.
TEST(NetworkStart, LongClipsHoldOutAtMost64Frames) {
  Fixture f;
  const std::vector<SparseDepth> eight = f.points(20, false);
  for (const int frames : {8, 300}) {
    std::vector<SparseDepth> s;
    for (int k = 0; k < frames; ++k) s.push_back(eight[size_t(k % kFrames)]);
    auto net = tiny_net();
    NetworkStartOptions o;
    o.warmup_steps = 1;
    const auto load = [&f](int k) { return f.images[size_t(k % kFrames)]; };
    const nlohmann::json info = start_default_network(*net, load, s, o);
    const int every = frames == 8 ? 4 : 5;  // 300 frames: ceil(300 / 64) = 5
    EXPECT_EQ(info["warmup_held_out"],
              "every " + std::to_string(every) + "th frame with sparse points held out");
    EXPECT_EQ(info["warmup_held_out_frames"].get<int>(), frames / every);
    EXPECT_LE(info["warmup_held_out_frames"].get<int>(), 64);
  }
}

}  // namespace
}  // namespace cvd
