// The depth networks (MiDaS v2, MiDaS v2.1 small, Mannequin hourglass) against PyTorch: tiny-width
// fixtures (tools/reference/gen_model_fixtures.py; definitions in midas_models.py and
// mannequin_model.py, checked at width 1 against the upstream code by verify_reference_models.py)
// give the weights, the input, the raw output, the loss sum(output * R), every parameter gradient
// and the BN running statistics after a train-mode step, all computed by PyTorch in float64.
// The full-size networks must have the published parameter counts and the released state-dict
// names and shapes.
//
// Error metrics: output max error / output range; loss relative; a gradient's max error / max(its
// max |ref|, 1e-4 x the model's largest gradient) (some gradients are mathematically zero, e.g.
// of a conv bias before a train-mode BN, and PyTorch's are round-off); running stats max error /
// max(max |ref|, 1).
// Tolerances: f64: output 1e-9, loss 1e-10, gradients and running stats 1e-8.
//   f32: output 1e-4, loss 1e-5, gradients and running stats 2e-4, or 16x PyTorch's own float32
//   error on that tensor where larger (recorded by the generator: the tiny train-mode networks are
//   ill-conditioned, PyTorch f32 itself is off by up to ~3e-3 on MiDaS v2 gradients).
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <set>

#include "engine/autograd.h"
#include "engine/cvdw.h"
#include "engine/ops.h"
#include "models/depth_net.h"
#include "models/depth_net_state.h"
#include "tests/test_support.h"

namespace cvd {
namespace {

std::filesystem::path fixture_path(const std::string& arch) {
  return test::source_dir() / "tests/data/models" / (arch + "_fixture.cvdw");
}

struct Tolerances {
  double output, loss, grad;
};
const Tolerances kF32{1e-4, 1e-5, 2e-4};
const Tolerances kF64{1e-9, 1e-10, 1e-8};

double max_abs(const std::vector<double>& v) {
  double m = 0;
  for (double x : v) m = std::max(m, std::abs(x));
  return m;
}

// max |a - b| over the elements (shapes must agree).
double max_abs_diff(const Tensor& a, const Tensor& b) {
  EXPECT_EQ(shape_str(a.shape()), shape_str(b.shape()));
  const auto va = a.to_vector(), vb = b.to_vector();
  if (va.size() != vb.size()) return INFINITY;
  double m = 0;
  for (size_t i = 0; i < va.size(); ++i) m = std::max(m, std::abs(va[i] - vb[i]));
  return m;
}

class ModelFixture {
 public:
  explicit ModelFixture(const std::string& arch) : reader_(fixture_path(arch)) {
    const auto& cfg = reader_.header().config;
    EXPECT_EQ(cfg.at("arch").get<std::string>(), arch);
    width_ = cfg.at("width").get<double>();
    f32_errors_ = cfg.at("pytorch_f32_error");
    for (const auto& e : reader_.header().tensors) {
      if (e.name.rfind("param/", 0) == 0) state_.emplace(e.name.substr(6), reader_.tensor(e.name));
    }
  }
  double width() const { return width_; }
  const std::map<std::string, Tensor>& state() const { return state_; }
  bool has(const std::string& name) const { return reader_.contains(name); }
  Tensor get(const std::string& name) const { return reader_.tensor(name); }
  // PyTorch's float32 error on reference tensor `name` (0 when not recorded).
  double pytorch_f32_error(const std::string& name) const {
    return f32_errors_.contains(name) ? f32_errors_.at(name).get<double>() : 0.0;
  }
  std::vector<std::string> names_with_prefix(const std::string& prefix) const {
    std::vector<std::string> out;
    for (const auto& e : reader_.header().tensors) {
      if (e.name.rfind(prefix, 0) == 0) out.push_back(e.name.substr(prefix.size()));
    }
    return out;
  }

 private:
  CvdwReader reader_;
  double width_ = 0;
  nlohmann::json f32_errors_;
  std::map<std::string, Tensor> state_;
};

std::unique_ptr<DepthNet> load_net(const std::string& arch, const ModelFixture& fx) {
  Generator gen(99);
  auto net = create_depth_net(arch, fx.width(), gen);
  const LoadStateReport report = load_depth_net_state(*net, fx.state());
  EXPECT_TRUE(report.missing.empty());
  EXPECT_EQ(report.loaded, net->named_state().size());
  // Only MiDaS's unused refinenet4.resConfUnit1 is left over (conv1/conv2 weight and bias).
  EXPECT_EQ(report.unexpected.size(), arch == "mannequin" ? 0u : 4u);
  for (const auto& n : report.unexpected) {
    EXPECT_EQ(n.rfind("scratch.refinenet4.resConfUnit1.", 0), 0u) << n;
  }
  return net;
}

// One forward + backward in the given BN mode and dtype, compared with the fixture.
void check_mode(const std::string& arch, const std::string& mode, DType dtype,
                const Tolerances& tol) {
  SCOPED_TRACE(arch + " " + mode + (dtype == DType::f32 ? " f32" : " f64"));
  ModelFixture fx(arch);
  auto net = load_net(arch, fx);
  net->to(dtype);
  net->train(mode == "train");

  // The tolerance for reference tensor `key`.
  auto tol_for = [&](const std::string& key, double fixed) {
    return dtype == DType::f32 ? std::max(fixed, 16 * fx.pytorch_f32_error(key)) : fixed;
  };
  const Tensor rgb = fx.get("input").to(dtype);
  const Tensor R = fx.get("R").to(dtype);
  const Tensor out = net->forward_raw(net->normalize_input(rgb));
  const Tensor loss = sum(mul(out, R));
  loss.backward();

  // Output, relative to the reference output's range.
  const Tensor ref_out = fx.get(mode + "/output");
  const auto ro = ref_out.to_vector();
  const auto [lo, hi] = std::minmax_element(ro.begin(), ro.end());
  const double range = *hi - *lo;
  ASSERT_GT(range, 0.0);
  EXPECT_LE(max_abs_diff(out, ref_out), tol_for(mode + "/output", tol.output) * range)
      << "output range " << range;

  const double ref_loss = fx.get(mode + "/loss").item();
  EXPECT_NEAR(loss.item(), ref_loss,
              tol_for(mode + "/loss", tol.loss) * std::max(1.0, std::abs(ref_loss)));

  // Every parameter gradient; parameters the output does not use (Mannequin's confidence head)
  // have none in PyTorch and must get none (or zero) here.
  std::set<std::string> reference_grads;
  double largest_grad = 0;
  for (const auto& n : fx.names_with_prefix(mode + "/grad/")) {
    reference_grads.insert(n);
    largest_grad = std::max(largest_grad, max_abs(fx.get(mode + "/grad/" + n).to_vector()));
  }
  ASSERT_GT(largest_grad, 0.0);
  size_t compared = 0;
  for (const auto& [name, p] : net->named_parameters()) {
    const std::string key = mode + "/grad/" + name;
    if (!reference_grads.count(name)) {
      if (p.grad().defined()) {
        EXPECT_EQ(max_abs(p.grad().to_vector()), 0.0) << name;
      }
      continue;
    }
    reference_grads.erase(name);
    ASSERT_TRUE(p.grad().defined()) << "no gradient for " << name;
    EXPECT_EQ(p.grad().dtype(), dtype) << name;
    const Tensor ref = fx.get(key);
    const double scale = std::max(max_abs(ref.to_vector()), 1e-4 * largest_grad);
    EXPECT_LE(max_abs_diff(p.grad(), ref), tol_for(key, tol.grad) * scale)
        << "gradient of " << name << " (scale " << scale << ")";
    ++compared;
  }
  // PyTorch's gradients all belong to parameters of ours (none left over).
  EXPECT_TRUE(reference_grads.empty()) << *reference_grads.begin();
  EXPECT_GT(compared, 20u);

  if (mode == "train") {
    size_t buffers = 0;
    for (const auto& [name, b] : net->named_buffers()) {
      const std::string key = "train/state/" + name;
      ASSERT_TRUE(fx.has(key)) << key;
      const Tensor ref = fx.get(key);
      const double scale = max_abs(ref.to_vector());
      EXPECT_LE(max_abs_diff(b, ref), tol_for(key, tol.grad) * std::max(scale, 1.0))
          << "buffer " << name;
      ++buffers;
    }
    EXPECT_GT(buffers, 10u);
  }
}

class ModelParity : public ::testing::TestWithParam<std::string> {};

TEST_P(ModelParity, EvalModeF32) { check_mode(GetParam(), "eval", DType::f32, kF32); }
TEST_P(ModelParity, TrainModeF32) { check_mode(GetParam(), "train", DType::f32, kF32); }
TEST_P(ModelParity, EvalModeF64) { check_mode(GetParam(), "eval", DType::f64, kF64); }
TEST_P(ModelParity, TrainModeF64) { check_mode(GetParam(), "train", DType::f64, kF64); }

TEST_P(ModelParity, OutputBiasIsTheLastConvBias) {
  const std::string arch = GetParam();
  ModelFixture fx(arch);
  auto net = load_net(arch, fx);
  const std::string last = arch == "mannequin" ? "pred_layer.bias" : "scratch.output_conv.4.bias";
  const Tensor bias = net->output_bias();
  ASSERT_TRUE(bias.defined());
  EXPECT_EQ(bias.numel(), 1);
  EXPECT_TRUE(bias.same(net->find_tensor(last)));
  // The fixture raised this bias to a known value; loading must have reached it.
  EXPECT_DOUBLE_EQ(bias.item(), fx.state().at(last).item());
}

TEST_P(ModelParity, RejectsMisalignedInput) {
  const std::string arch = GetParam();
  Generator gen(1);
  auto net = create_depth_net(arch, arch == "mannequin" ? 0.0625 : 1.0 / 64, gen);
  const int a = net->alignment();
  EXPECT_EQ(a, arch == "mannequin" ? 16 : 32);
  const Tensor bad = Tensor::zeros({1, 3, a * 2, a * 2 + a / 2});
  EXPECT_THROW(net->forward_raw(bad), Error);
  EXPECT_THROW(net->forward_raw(Tensor::zeros({1, 1, a, a})), Error);
}

// execution_order (used to match imported graphs by structure) covers every parameter exactly
// once.
TEST_P(ModelParity, ExecutionOrderCoversEveryParameterOnce) {
  Generator gen(1);
  auto net = create_depth_net(GetParam(), GetParam() == "mannequin" ? 0.0625 : 1.0 / 64, gen);
  const auto order = net->execution_order();
  ASSERT_FALSE(order.empty());
  for (const auto& [name, _] : net->named_parameters()) {
    int covering = 0;
    for (const auto& prefix : order) {
      if (prefix.empty() || name.rfind(prefix + ".", 0) == 0) ++covering;
    }
    EXPECT_EQ(covering, 1) << name;
  }
}

INSTANTIATE_TEST_SUITE_P(DepthNets, ModelParity,
                         ::testing::Values("midas_v2", "midas_small", "mannequin"));

TEST(Models, ArchitecturesAreRegistered) {
  const auto archs = depth_net_archs();
  for (const char* a : {"mannequin", "midas_v2", "midas_small"}) {
    EXPECT_NE(std::find(archs.begin(), archs.end(), a), archs.end()) << a;
  }
  Generator gen(0);
  EXPECT_THROW(create_depth_net("midas_v3", 1.0, gen), Error);
  EXPECT_THROW(create_depth_net("midas_v2", 0.3, gen), Error);     // not a power of two
  EXPECT_THROW(create_depth_net("midas_small", 1.5, gen), Error);  // above 1
  EXPECT_THROW(create_depth_net("mannequin", 0.1, gen), Error);    // 16 * width not whole
}

TEST(Models, ImageNetNormalisation) {
  Generator gen(0);
  auto net = create_depth_net("midas_small", 1.0 / 32, gen);
  const Tensor rgb = Tensor::full({1, 3, 1, 2}, 0.5);
  const auto v = net->normalize_input(rgb).to_vector();
  const double mean[3] = {0.485, 0.456, 0.406}, stdv[3] = {0.229, 0.224, 0.225};
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(v[c * 2], (0.5 - mean[c]) / stdv[c], 1e-6);
    EXPECT_NEAR(v[c * 2 + 1], (0.5 - mean[c]) / stdv[c], 1e-6);
  }
}

// Full-size networks: the published parameter counts (excluding the unused
// refinenet4.resConfUnit1) and the released state dict's names and shapes.
class FullSize : public ::testing::TestWithParam<std::pair<std::string, int64_t>> {};

TEST_P(FullSize, ParameterCountAndStateNames) {
  const auto& [arch, count] = GetParam();
  std::ifstream in(test::source_dir() / "tests/data/models/full_size_state.json");
  ASSERT_TRUE(in.good());
  const auto released = nlohmann::json::parse(in).at(arch);
  Generator gen(5);
  auto net = create_depth_net(arch, 1.0, gen);
  EXPECT_EQ(net->parameter_count(), count);

  // named_state lists parameters before buffers; PyTorch interleaves them per module: compare
  // by name.
  std::map<std::string, Shape> mine;
  for (const auto& [n, t] : net->named_state()) mine.emplace(n, t.shape());
  size_t used = 0;
  for (const auto& entry : released) {
    const std::string name = entry.at(0).get<std::string>();
    if (is_unused_depth_net_state(arch, name)) continue;
    ++used;
    auto it = mine.find(name);
    ASSERT_NE(it, mine.end()) << "missing " << name;
    EXPECT_EQ(shape_str(it->second), shape_str(entry.at(1).get<Shape>())) << name;
  }
  EXPECT_EQ(used, mine.size());
}

INSTANTIATE_TEST_SUITE_P(DepthNets, FullSize,
                         ::testing::Values(std::make_pair(std::string("midas_v2"), 104182785LL),
                                           std::make_pair(std::string("midas_small"), 16600929LL),
                                           std::make_pair(std::string("mannequin"), 5357730LL)),
                         [](const auto& info) { return info.param.first; });

}  // namespace
}  // namespace cvd
