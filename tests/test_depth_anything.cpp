// Depth Anything V2 (models/depth_anything_v2.h) against PyTorch: a reduced configuration (4
// blocks of width 24, a 4 x 4 position grid; tools/reference/gen_depth_anything_fixture.py with
// the independent definition depth_anything_v2_model.py) with seeded random weights: raw output,
// the loss sum(output * R) and every parameter gradient, computed by PyTorch in float64, on a
// 56 x 42 input (the position embedding resized bicubically with DINOv2's scale factors) and the
// forward on a 56 x 56 input (the embedding as is). The network has no batch norm or dropout, so
// train mode must give exactly the eval-mode references. The full-size ViT-S must have the
// reference's parameter count and state names and shapes, in order.
//
// Metrics and tolerances as tests/test_models.cpp: output max error / output range, loss
// relative, a gradient's max error / max(its max |ref|, 1e-4 x the largest gradient).
//   f64: output 1e-9, loss 1e-10, gradients 1e-8.
//   f32: output 1e-4, loss 1e-5, gradients 2e-4, or 16x PyTorch's own float32 error where larger.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <set>

#include "engine/autograd.h"
#include "engine/cvdw.h"
#include "engine/ops.h"
#include "models/depth_anything_v2.h"
#include "models/depth_net_architectures.h"
#include "models/depth_net_state.h"
#include "tests/depth_anything_test_config.h"
#include "tests/test_support.h"

namespace cvd {
namespace {

const std::filesystem::path kFixture =
    test::source_dir() / "tests/data/models/depth_anything_v2_fixture.cvdw";

double max_abs(const std::vector<double>& v) {
  double m = 0;
  for (double x : v) m = std::max(m, std::abs(x));
  return m;
}

double max_abs_diff(const Tensor& a, const Tensor& b) {
  EXPECT_EQ(shape_str(a.shape()), shape_str(b.shape()));
  const auto va = a.to_vector(), vb = b.to_vector();
  if (va.size() != vb.size()) return INFINITY;
  double m = 0;
  for (size_t i = 0; i < va.size(); ++i) m = std::max(m, std::abs(va[i] - vb[i]));
  return m;
}

struct Fixture {
  CvdwReader reader{kFixture};
  nlohmann::json config = reader.header().config;
  std::unique_ptr<DepthAnythingV2Net> net() const {
    Generator gen(5);
    auto n = std::make_unique<DepthAnythingV2Net>(
        test::depth_anything_config_from(config.at("dav2_config")), gen);
    std::map<std::string, Tensor> state;
    for (const auto& e : reader.header().tensors)
      if (e.name.rfind("param/", 0) == 0) state.emplace(e.name.substr(6), reader.tensor(e.name));
    const LoadStateReport r = load_depth_net_state(*n, state);
    EXPECT_TRUE(r.missing.empty() && r.unexpected.empty()) << "every name matches, none left over";
    EXPECT_EQ(r.loaded, n->named_state().size());
    return n;
  }
  double pytorch_f32_error(const std::string& key) const {
    const auto& e = config.at("pytorch_f32_error");
    return e.contains(key) ? e.at(key).get<double>() : 0.0;
  }
};

void check_parity(bool train, DType dtype) {
  SCOPED_TRACE(std::string(train ? "train" : "eval") + (dtype == DType::f32 ? " f32" : " f64"));
  Fixture fx;
  auto net = fx.net();
  net->to(dtype);
  net->train(train);
  const bool f32 = dtype == DType::f32;
  auto tol = [&](const std::string& key, double f32_tol, double f64_tol) {
    return f32 ? std::max(f32_tol, 16 * fx.pytorch_f32_error(key)) : f64_tol;
  };
  const Tensor out = net->forward_raw(net->normalize_input(fx.reader.tensor("input").to(dtype)));
  const Tensor loss = sum(mul(out, fx.reader.tensor("R").to(dtype)));
  loss.backward();

  const Tensor ref_out = fx.reader.tensor("eval/output");
  const auto ro = ref_out.to_vector();
  const auto [lo, hi] = std::minmax_element(ro.begin(), ro.end());
  ASSERT_GT(*hi - *lo, 0.0);
  EXPECT_LE(max_abs_diff(out, ref_out), tol("eval/output", 1e-4, 1e-9) * (*hi - *lo));
  const double ref_loss = fx.reader.tensor("eval/loss").item();
  EXPECT_NEAR(loss.item(), ref_loss,
              tol("eval/loss", 1e-5, 1e-10) * std::max(1.0, std::abs(ref_loss)));

  std::set<std::string> ref_grads;
  double largest = 0;
  for (const auto& e : fx.reader.header().tensors)
    if (e.name.rfind("eval/grad/", 0) == 0) {
      ref_grads.insert(e.name.substr(10));
      largest = std::max(largest, max_abs(fx.reader.tensor(e.name).to_vector()));
    }
  ASSERT_GT(largest, 0.0);
  size_t compared = 0;
  for (const auto& [name, p] : net->named_parameters()) {
    if (!ref_grads.count(name)) {
      // mask_token and refinenet4.resConfUnit1: unused by the forward, as in PyTorch.
      if (p.grad().defined()) {
        EXPECT_EQ(max_abs(p.grad().to_vector()), 0.0) << name;
      }
      continue;
    }
    ref_grads.erase(name);
    ASSERT_TRUE(p.grad().defined()) << "no gradient for " << name;
    const std::string key = "eval/grad/" + name;
    const Tensor ref = fx.reader.tensor(key);
    const double scale = std::max(max_abs(ref.to_vector()), 1e-4 * largest);
    EXPECT_LE(max_abs_diff(p.grad(), ref), tol(key, 2e-4, 1e-8) * scale)
        << "gradient of " << name << " (scale " << scale << ")";
    ++compared;
  }
  EXPECT_TRUE(ref_grads.empty()) << *ref_grads.begin();
  EXPECT_GT(compared, 60u);
}

TEST(DepthAnythingV2, EvalModeF64) { check_parity(false, DType::f64); }
TEST(DepthAnythingV2, EvalModeF32) { check_parity(false, DType::f32); }
TEST(DepthAnythingV2, TrainModeF64) { check_parity(true, DType::f64); }
TEST(DepthAnythingV2, TrainModeF32) { check_parity(true, DType::f32); }

TEST(DepthAnythingV2, SquareInputUsesThePositionEmbeddingAsIs) {
  Fixture fx;
  auto net = fx.net();
  net->to(DType::f64);
  NoGradGuard ng;
  const Tensor out =
      net->forward_raw(net->normalize_input(fx.reader.tensor("square/input").to(DType::f64)));
  const Tensor ref = fx.reader.tensor("square/output");
  const auto rv = ref.to_vector();
  const auto [lo, hi] = std::minmax_element(rv.begin(), rv.end());
  EXPECT_LE(max_abs_diff(out, ref), 1e-9 * (*hi - *lo));
}

TEST(DepthAnythingV2, LargerEncodersScaleByWidth) {
  // Half width keeps the heads (64 -> 32 channels each) and halves every channel count.
  Generator gen(2);
  const auto half = create_depth_net("depth_anything_v2_vitb", 0.5, gen);
  const auto& cfg = dynamic_cast<const DepthAnythingV2Net&>(*half).config();
  EXPECT_EQ(cfg.vit.embed_dim, 384);
  EXPECT_EQ(cfg.vit.heads, 12);
  EXPECT_EQ(cfg.features, 64);
  EXPECT_EQ(cfg.out_channels, (std::array<int64_t, 4>{48, 96, 192, 384}));
  EXPECT_EQ(half->arch(), "depth_anything_v2_vitb");
  const auto large_net = create_depth_net("depth_anything_v2_vitl", 1.0 / 16, gen);
  const auto& large = dynamic_cast<const DepthAnythingV2Net&>(*large_net);
  EXPECT_EQ(large.config().vit.depth, 24);
  EXPECT_EQ(large.config().layers, (std::array<int, 4>{4, 11, 17, 23}));
  // ViT-L's 16 heads need 16 channels or more: width 1/128 leaves 8.
  EXPECT_THROW(create_depth_net("depth_anything_v2_vitl", 1.0 / 128, gen), Error);
}

TEST(DepthAnythingV2, TableRowAndInputChecks) {
  const DepthNetArchitecture& a = depth_net_architecture("depth_anything_v2");
  EXPECT_EQ(a.alignment, 14);
  EXPECT_EQ(a.output_kind, DepthOutputKind::inverse_depth);
  Generator gen(1);
  auto net = create_depth_net("depth_anything_v2", 1.0 / 16, gen);
  EXPECT_EQ(net->alignment(), 14);
  EXPECT_THROW(net->forward_raw(Tensor::zeros({1, 3, 28, 30})), Error);
  EXPECT_THROW(net->forward_raw(Tensor::zeros({1, 1, 28, 28})), Error);
  EXPECT_THROW(create_depth_net("depth_anything_v2", 0.3, gen), Error);
  NoGradGuard ng;
  const Tensor out = net->forward_raw(Tensor::zeros({1, 3, 42, 28}));
  EXPECT_EQ(out.shape(), (Shape{1, 1, 42, 28}));
  // The output layer is the last 1x1 conv (the flat-plane start zeroes its weight).
  EXPECT_TRUE(net->output_bias().same(net->find_tensor("depth_head.scratch.output_conv2.2.bias")));
  EXPECT_TRUE(
      net->output_weight().same(net->find_tensor("depth_head.scratch.output_conv2.2.weight")));
}

TEST(DepthAnythingV2, ExecutionOrderCoversEveryUsedParameterOnce) {
  Generator gen(1);
  auto net = create_depth_net("depth_anything_v2", 1.0 / 16, gen);
  const auto order = net->execution_order();
  for (const auto& [name, _] : net->named_parameters()) {
    int covering = 0;
    for (const auto& prefix : order)
      if (name.rfind(prefix + ".", 0) == 0) ++covering;
    const bool unused = name.rfind("depth_head.scratch.refinenet4.resConfUnit1.", 0) == 0;
    EXPECT_EQ(covering, unused ? 0 : 1) << name;
  }
}

}  // namespace
}  // namespace cvd
