// FlowNet2 (models/flownet2.h) against PyTorch: a tiny-width fixture
// (tools/reference/gen_flownet2_fixture.py, network in tools/reference/flownet2_model.py) gives
// the weights, an image pair, each sub-network's flow2 inside the chain and the final flow, all
// computed by PyTorch in float64. Each sub-network is fed the input rebuilt from the
// reference's upstream flows, so a mismatch is located; the full chain is checked end to end.
// The full-size network must have the published parameter counts and upstream names.
//
// Tolerances (max abs error relative to the largest magnitude of the reference tensor):
//   f32: 1e-5;  f64: 1e-11 (measured: 6e-7 and 1.3e-15).
#include <gtest/gtest.h>

#include <fmt/format.h>
#include <algorithm>
#include <cmath>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "engine/autograd.h"
#include "engine/cvdw.h"
#include "engine/module_weights.h"
#include "engine/ops.h"
#include "models/flownet2.h"
#include "pipeline/flow/flow_flownet2.h"
#include "pipeline/io/flow_io.h"
#include "tests/test_support.h"

namespace cvd {
namespace {

constexpr double kF32Tol = 1e-5;
constexpr double kF64Tol = 1e-11;

double max_abs(const Tensor& t) {
  double m = 0;
  for (double v : t.to_vector()) m = std::max(m, std::abs(v));
  return m;
}

// max |a - b| / max(|b|) (shapes must agree).
double relative_error(const Tensor& a, const Tensor& b) {
  EXPECT_EQ(shape_str(a.shape()), shape_str(b.shape()));
  const auto va = a.to_vector(), vb = b.to_vector();
  if (va.size() != vb.size()) return INFINITY;
  double m = 0;
  for (size_t i = 0; i < va.size(); ++i) m = std::max(m, std::abs(va[i] - vb[i]));
  return m / std::max(max_abs(b), 1e-12);
}

class FlowNet2Fixture {
 public:
  FlowNet2Fixture() : reader_(test::source_dir() / "tests/data/models/flownet2_fixture.cvdw") {
    EXPECT_EQ(reader_.header().config.at("arch").get<std::string>(), "flownet2");
    width_ = reader_.header().config.at("width").get<double>();
    for (const auto& e : reader_.header().tensors)
      if (e.name.rfind("param/", 0) == 0) state_.emplace(e.name.substr(6), reader_.tensor(e.name));
  }
  std::shared_ptr<FlowNet2> network(DType dtype) const {
    Generator gen(1);
    auto net = std::make_shared<FlowNet2>(width_, gen);
    net->to(dtype);
    const LoadStateReport r = net->load_state(state_, /*strict=*/true);
    EXPECT_EQ(r.loaded, state_.size());
    net->eval();
    return net;
  }
  Tensor get(const std::string& name, DType dtype) const { return reader_.tensor(name).to(dtype); }

 private:
  CvdwReader reader_;
  double width_ = 0;
  std::map<std::string, Tensor> state_;
};

class FlowNet2Parity : public ::testing::TestWithParam<DType> {};

TEST_P(FlowNet2Parity, ChainAndSubNetworksMatchPyTorch) {
  const DType dt = GetParam();
  const double tol = dt == DType::f32 ? kF32Tol : kF64Tol;
  FlowNet2Fixture fx;
  auto net = fx.network(dt);
  NoGradGuard ng;
  const Tensor img0 = fx.get("input/img0", dt), img1 = fx.get("input/img1", dt);
  FlowNet2Trace trace;
  const Tensor out = net->forward_pair(img0, img1, &trace);
  EXPECT_LE(relative_error(out, fx.get("output", DType::f64)), tol) << "FlowNet2 output";
  EXPECT_GT(max_abs(fx.get("output", DType::f64)), 0.5) << "fixture flow should be a few px";

  // Each sub-network on the input rebuilt from the reference's upstream outputs.
  const Tensor x = FlowNet2::normalize_pair(img0, img1);
  const Tensor ref_c = fx.get("flownetc", dt), ref_s1 = fx.get("flownets_1", dt);
  const Tensor ref_s2 = fx.get("flownets_2", dt), ref_sd = fx.get("flownets_d", dt);
  auto up_bilinear = [](const Tensor& f) {
    return upsample_bilinear2d(mul_scalar(f, FlowNet2::kDivFlow), f.size(2) * 4, f.size(3) * 4,
                               false);
  };
  EXPECT_LE(relative_error(net->flownetc().forward(x), ref_c), tol) << "flownetc";
  EXPECT_LE(
      relative_error(net->flownets_1().forward(FlowNet2::refinement_input(x, up_bilinear(ref_c))),
                     ref_s1),
      tol)
      << "flownets_1";
  EXPECT_LE(
      relative_error(net->flownets_2().forward(FlowNet2::refinement_input(x, up_bilinear(ref_s1))),
                     ref_s2),
      tol)
      << "flownets_2";
  EXPECT_LE(relative_error(net->flownets_d().forward(x), ref_sd), tol) << "flownets_d";
  // The chain's own sub-network outputs.
  EXPECT_LE(relative_error(trace.flownetc, ref_c), tol);
  EXPECT_LE(relative_error(trace.flownets_1, ref_s1), tol);
  EXPECT_LE(relative_error(trace.flownets_2, ref_s2), tol);
  EXPECT_LE(relative_error(trace.flownets_d, ref_sd), tol);
}

INSTANTIATE_TEST_SUITE_P(DTypes, FlowNet2Parity, ::testing::Values(DType::f32, DType::f64),
                         [](const ::testing::TestParamInfo<DType>& i) {
                           return std::string(i.param == DType::f32 ? "f32" : "f64");
                         });

TEST(FlowNet2, FullSizeParameterCountsAndNames) {
  Generator gen(0);
  FlowNet2 net(1.0, gen);
  EXPECT_EQ(net.parameter_count(), 162518834);
  EXPECT_EQ(net.flownetc().parameter_count(), 39175298);
  EXPECT_EQ(net.flownets_1().parameter_count(), 38695322);
  EXPECT_EQ(net.flownets_2().parameter_count(), 38695322);
  EXPECT_EQ(net.flownets_d().parameter_count(), 45371666);
  EXPECT_EQ(net.flownetfusion().parameter_count(), 581226);
  const auto state = net.state_dict();
  EXPECT_EQ(shape_str(state.at("flownetc.conv1.0.weight").shape()), shape_str({64, 3, 7, 7}));
  EXPECT_EQ(shape_str(state.at("flownetc.conv3_1.0.weight").shape()), shape_str({256, 473, 3, 3}));
  EXPECT_EQ(shape_str(state.at("flownets_1.conv1.0.weight").shape()), shape_str({64, 12, 7, 7}));
  EXPECT_EQ(shape_str(state.at("flownets_d.inter_conv5.0.weight").shape()),
            shape_str({512, 1026, 3, 3}));
  EXPECT_EQ(shape_str(state.at("flownetfusion.conv0.0.weight").shape()), shape_str({64, 11, 3, 3}));
  EXPECT_EQ(shape_str(state.at("flownetfusion.deconv0.0.weight").shape()),
            shape_str({162, 16, 4, 4}));
  // FlowNetS's flow upsampling has no bias; C, SD and Fusion's have one.
  EXPECT_EQ(state.count("flownets_2.upsampled_flow6_to_5.bias"), 0u);
  EXPECT_EQ(state.count("flownetc.upsampled_flow6_to_5.bias"), 1u);
  EXPECT_EQ(state.count("flownets_d.upsampled_flow3_to_2.bias"), 1u);
  EXPECT_EQ(state.count("flownetfusion.upsampled_flow1_to_0.bias"), 1u);
}

TEST(FlowNet2, CorrelationFindsAKnownShift) {
  // b is a shifted right by 2 px and down by 4 px: FlowNetC's displacement (ti, tj) = (1, 2)
  // (stride2 2) sees a . a / C at every interior pixel; the opposite displacement does not.
  Generator gen(3);
  const int64_t c = 5, h = 12, w = 14;
  const Tensor a = Tensor::randn({1, c, h, w}, gen, DType::f64);
  const Tensor b = pad(narrow(narrow(a, 2, 0, h - 4), 3, 0, w - 2), {2, 0, 4, 0});
  CorrelationParams p;
  p.pad = 20;
  p.kernel_size = 1;
  p.max_displacement = 20;
  p.stride1 = 1;
  p.stride2 = 2;
  const Tensor y = correlation(a, b, p);
  ASSERT_EQ(shape_str(y.shape()), shape_str({1, 441, h, w}));
  const Tensor norm2 = mul_scalar(sum(square(a), {1}), 1.0 / static_cast<double>(c));
  const int64_t match = (2 + 10) * 21 + (1 + 10), opposite = (-2 + 10) * 21 + (-1 + 10);
  const auto yv = y.to_vector(), nv = norm2.to_vector();
  for (int64_t yy = 0; yy + 4 < h; ++yy)
    for (int64_t xx = 0; xx + 2 < w; ++xx) {
      const double expect = nv[static_cast<size_t>(yy * w + xx)];
      EXPECT_NEAR(yv[static_cast<size_t>((match * h + yy) * w + xx)], expect, 1e-12);
      EXPECT_GT(std::abs(yv[static_cast<size_t>((opposite * h + yy) * w + xx)] - expect), 1e-6);
    }
}

TEST(FlowNet2, ChannelNormGradientIsZeroAtZero) {
  Tensor x = Tensor::zeros({1, 3, 2, 2}, DType::f64);
  x.requires_grad_(true);
  const Tensor y = channel_norm(x);
  const auto g = grad(sum(y), {x});
  for (double v : g[0].to_vector()) EXPECT_EQ(v, 0.0);
}

TEST(FlowNet2, Resample2dIsFlownetWarping) {
  // Integer flow (1, 0) reads the right neighbour; beyond the border the edge value repeats.
  const Tensor img = Tensor::from_vector(std::vector<double>{0, 1, 2, 3, 10, 11, 12, 13},
                                         {1, 1, 2, 4}, DType::f64);
  const Tensor flow = concat(
      {Tensor::full({1, 1, 2, 4}, 1.0, DType::f64), Tensor::full({1, 1, 2, 4}, 0.5, DType::f64)},
      1);
  const auto v = FlowNet2::resample2d(img, flow).to_vector();
  const std::vector<double> expect{6,  7,  8,  8,
                                   11, 12, 13, 13};  // y 0.5: mean of rows; y 1.5: row 1
  ASSERT_EQ(v.size(), expect.size());
  for (size_t i = 0; i < v.size(); ++i) EXPECT_NEAR(v[i], expect[i], 1e-12) << i;
}

TEST(FlowNet2Estimator, MatchesTheNetworkAndRescalesToTheInputSize) {
  FlowNet2Fixture fx;
  auto net = fx.network(DType::f32);
  // The fixture's first image pair as 8-bit BGR (its values are integers in [0, 255]).
  const Tensor img0 = fx.get("input/img0", DType::f64), img1 = fx.get("input/img1", DType::f64);
  const int64_t h = img0.size(2), w = img0.size(3);
  auto to_bgr = [h, w](const Tensor& t) {
    const auto v = t.to_vector();
    cv::Mat m(static_cast<int>(h), static_cast<int>(w), CV_8UC3);
    for (int64_t y = 0; y < h; ++y)
      for (int64_t x = 0; x < w; ++x)
        for (int c = 0; c < 3; ++c)
          m.at<cv::Vec3b>(static_cast<int>(y), static_cast<int>(x))[2 - c] =
              static_cast<uint8_t>(v[static_cast<size_t>((c * h + y) * w + x)]);
    return m;
  };
  const cv::Mat a = to_bgr(narrow(img0, 0, 0, 1)), b = to_bgr(narrow(img1, 0, 0, 1));

  test::TempDir dir;
  save_weights(*net, dir / "tiny.cvdw", "flownet2", {{"width", net->width()}});
  FlowNet2Estimator est(dir / "tiny.cvdw");
  EXPECT_EQ(est.network().width(), net->width());
  const cv::Mat flow = est.estimate(a, b);
  ASSERT_EQ(flow.type(), CV_32FC2);
  ASSERT_EQ(flow.size(), a.size());
  const auto ref = narrow(fx.get("output", DType::f64), 0, 0, 1).contiguous().to_vector();
  const double range = max_abs(fx.get("output", DType::f64));
  double err = 0;
  for (int64_t y = 0; y < h; ++y)
    for (int64_t x = 0; x < w; ++x)
      for (int c = 0; c < 2; ++c)
        err =
            std::max(err, std::abs(flow.at<cv::Vec2f>(static_cast<int>(y), static_cast<int>(x))[c] -
                                   ref[static_cast<size_t>((c * h + y) * w + x)]));
  EXPECT_LE(err, kF32Tol * range);

  // A size that is not a multiple of 64: resized in, flow resized back with rescaled components.
  EXPECT_EQ(FlowNet2Estimator::network_size({100, 70}), cv::Size(128, 64));
  EXPECT_EQ(FlowNet2Estimator::network_size({20, 20}), cv::Size(64, 64));
  cv::Mat a2, b2;
  cv::resize(a, a2, {100, 70});
  cv::resize(b, b2, {100, 70});
  const cv::Mat flow2 = est.estimate(a2, b2);
  ASSERT_EQ(flow2.size(), cv::Size(100, 70));
  EXPECT_TRUE(cv::checkRange(flow2));
}

TEST(FlowNet2Cli, FlowMethodFlownet2WritesTheFlow) {
  FlowNet2Fixture fx;
  auto net = fx.network(DType::f32);
  test::TempDir dir;
  save_weights(*net, dir / "tiny.cvdw", "flownet2", {{"width", net->width()}});
  cv::Mat a(64, 128, CV_8UC3), b;
  cv::RNG(5).fill(a, cv::RNG::UNIFORM, 0, 256);
  cv::GaussianBlur(a, a, {0, 0}, 2.0);
  cv::warpAffine(a, b, cv::Matx23d(1, 0, 2, 0, 1, 1), a.size(), cv::INTER_LINEAR,
                 cv::BORDER_REFLECT);
  cv::imwrite((dir / "a.png").string(), a);
  cv::imwrite((dir / "b.png").string(), b);
  const auto r = test::run_cvd(fmt::format(
      "flow {} {} -o {} --method flownet2 --model {} --no-homography", (dir / "a.png").string(),
      (dir / "b.png").string(), (dir / "f.flo").string(), (dir / "tiny.cvdw").string()));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("flownet2"), std::string::npos) << r.output;
  const cv::Mat flow = read_flo(dir / "f.flo");
  EXPECT_EQ(flow.size(), a.size());
  // The same pair through the estimator directly gives the same flow.
  FlowNet2Estimator est(net);
  const cv::Mat direct =
      est.estimate(cv::imread((dir / "a.png").string()), cv::imread((dir / "b.png").string()));
  EXPECT_LE(cv::norm(flow, direct, cv::NORM_INF), 1e-5);

  const auto missing =
      test::run_cvd(fmt::format("flow {} {} -o {} --method flownet2", (dir / "a.png").string(),
                                (dir / "b.png").string(), (dir / "g.flo").string()));
  EXPECT_NE(missing.exit_code, 0);
  EXPECT_NE(missing.output.find("--model"), std::string::npos) << missing.output;
}

}  // namespace
}  // namespace cvd
