// Module tree (names, counts, modes, state loading), the standard layers (initialisation,
// shapes, BatchNorm running statistics) and module weights files.
#include <gtest/gtest.h>

#include <cmath>

#include "engine/autograd.h"
#include "engine/cvdw.h"
#include "engine/layers.h"
#include "engine/module_weights.h"
#include "engine/ops.h"
#include "tests/test_support.h"

namespace cvd {
namespace {

template <class Fn>
std::string error_of(Fn&& fn, ErrorCategory expected) {
  try {
    fn();
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), expected) << e.what();
    return e.what();
  }
  ADD_FAILURE() << "no error thrown";
  return "";
}

bool contains(const std::string& s, const std::string& part) {
  return s.find(part) != std::string::npos;
}

// conv1 -> bn1 -> layer1 (grouped conv without bias, non-affine BN, ReLU) -> mean -> fc.
class TinyNet : public Module {
 public:
  explicit TinyNet(uint64_t seed, DType dtype = DType::f32) {
    Generator gen(seed);
    conv1 = register_module(
        "conv1", std::make_shared<Conv2d>(Conv2dOptions(3, 4, 3).with_padding(1), gen, dtype));
    bn1 = register_module("bn1", std::make_shared<BatchNorm2d>(BatchNorm2dOptions(4), dtype));
    layer1 = register_module("layer1", std::make_shared<Sequential>());
    layer1->push_back(std::make_shared<Conv2d>(
        Conv2dOptions(4, 4, 3).with_padding(1).with_groups(2).with_bias(false), gen, dtype));
    layer1->push_back(
        std::make_shared<BatchNorm2d>(BatchNorm2dOptions(4).with_affine(false), dtype));
    layer1->push_back(std::make_shared<ReLU>());
    fc = register_module("fc", std::make_shared<Linear>(4, 2, gen, true, dtype));
  }
  std::string type_name() const override { return "TinyNet"; }
  Tensor forward(const Tensor& x) override {
    Tensor h = layer1->forward(bn1->forward(conv1->forward(x)));
    return fc->forward(mean(h, {2, 3}));
  }
  std::shared_ptr<Conv2d> conv1;
  std::shared_ptr<BatchNorm2d> bn1;
  std::shared_ptr<Sequential> layer1;
  std::shared_ptr<Linear> fc;
};

std::vector<std::string> names_of(const NamedTensors& v) {
  std::vector<std::string> out;
  for (const auto& [n, _] : v) out.push_back(n);
  return out;
}

TEST(Module, DottedNamesInRegistrationOrder) {
  TinyNet net(1);
  EXPECT_EQ(names_of(net.named_parameters()),
            (std::vector<std::string>{"conv1.weight", "conv1.bias", "bn1.weight", "bn1.bias",
                                      "layer1.0.weight", "fc.weight", "fc.bias"}));
  EXPECT_EQ(names_of(net.named_buffers()),
            (std::vector<std::string>{"bn1.running_mean", "bn1.running_var",
                                      "bn1.num_batches_tracked", "layer1.1.running_mean",
                                      "layer1.1.running_var", "layer1.1.num_batches_tracked"}));
  auto state = net.state_dict();
  EXPECT_EQ(state.size(), 13u);
  EXPECT_TRUE(state.at("layer1.1.running_var").same(net.find_tensor("layer1.1.running_var")));
  std::vector<std::string> modules;
  for (const auto& [n, _] : net.named_modules()) modules.push_back(n);
  EXPECT_EQ(modules, (std::vector<std::string>{"", "conv1", "bn1", "layer1", "layer1.0", "layer1.1",
                                               "layer1.2", "fc"}));
}

TEST(Module, ParameterCountsAndShapes) {
  TinyNet net(1);
  // conv1 4*3*3*3 + 4, bn1 4 + 4, layer1.0 4*(4/2)*3*3, fc 2*4 + 2.
  EXPECT_EQ(net.parameter_count(), 112 + 8 + 72 + 10);
  EXPECT_EQ(net.buffer_count(), (4 + 4 + 1) * 2);
  EXPECT_EQ(net.conv1->weight.shape(), (Shape{4, 3, 3, 3}));
  EXPECT_EQ(std::static_pointer_cast<Conv2d>((*net.layer1)[0])->weight.shape(),
            (Shape{4, 2, 3, 3}));
  EXPECT_FALSE(std::static_pointer_cast<Conv2d>((*net.layer1)[0])->bias.defined());
  EXPECT_EQ(net.bn1->num_batches_tracked.shape(), Shape{});
  for (const auto& [n, t] : net.named_parameters()) {
    EXPECT_TRUE(t.requires_grad()) << n;
    EXPECT_TRUE(t.is_leaf()) << n;
  }
  for (const auto& [n, t] : net.named_buffers()) EXPECT_FALSE(t.requires_grad()) << n;
}

TEST(Module, SharedParameterCountedOnce) {
  struct Tied : Module {
    Tied() {
      Generator gen(3);
      a = register_module("a", std::make_shared<Linear>(3, 3, gen));
      b = register_module("b", a);
    }
    std::shared_ptr<Linear> a, b;
  } tied;
  EXPECT_EQ(tied.parameter_count(), 12);
  EXPECT_EQ(tied.named_parameters().size(), 2u);
  EXPECT_EQ(tied.state_dict().size(), 4u);  // both names, as PyTorch's state_dict
}

TEST(Module, RegistrationRejectsBadAndDuplicateNames) {
  struct Bad : Module {
    void add(const std::string& n) { register_buffer(n, Tensor::zeros({1})); }
  } m;
  m.add("x");
  EXPECT_TRUE(contains(error_of([&] { m.add("x"); }, ErrorCategory::invalid_argument), "twice"));
  error_of([&] { m.add("a.b"); }, ErrorCategory::invalid_argument);
  error_of([&] { m.add(""); }, ErrorCategory::invalid_argument);
}

TEST(Module, TrainEvalPropagatesToEveryDescendant) {
  TinyNet net(1);
  for (const auto& [n, m] : net.named_modules()) EXPECT_TRUE(m->is_training()) << n;
  net.eval();
  for (const auto& [n, m] : net.named_modules()) EXPECT_FALSE(m->is_training()) << n;
  // A child added to a module in eval mode takes its mode.
  net.layer1->push_back(std::make_shared<Sigmoid>());
  EXPECT_FALSE((*net.layer1)[3]->is_training());
  net.train();
  for (const auto& [n, m] : net.named_modules()) EXPECT_TRUE(m->is_training()) << n;
  net.layer1->eval();
  EXPECT_TRUE(net.is_training());
  EXPECT_FALSE((*net.layer1)[1]->is_training());
}

TEST(Module, ZeroGradAndBackwardReachEveryParameter) {
  TinyNet net(2, DType::f64);
  Generator gen(5);
  Tensor x = Tensor::randn({2, 3, 5, 4}, gen, DType::f64);
  sum(net.forward(x)).backward();
  for (const auto& [n, t] : net.named_parameters()) {
    ASSERT_TRUE(t.grad().defined()) << n;
    EXPECT_EQ(t.grad().shape(), t.shape()) << n;
  }
  net.zero_grad();
  for (const auto& [n, t] : net.named_parameters()) EXPECT_FALSE(t.grad().defined()) << n;
}

TEST(Module, ToDtypeConvertsInPlaceKeepingHandles) {
  TinyNet net(1);
  Tensor handle = net.conv1->weight;
  std::vector<double> before = handle.to_vector();
  net.to(DType::f64);
  for (const auto& [n, t] : net.named_parameters()) EXPECT_EQ(t.dtype(), DType::f64) << n;
  EXPECT_EQ(net.bn1->running_var.dtype(), DType::f64);
  EXPECT_EQ(handle.dtype(), DType::f64);  // the member and outside handles see the new data
  EXPECT_TRUE(handle.requires_grad());
  EXPECT_EQ(handle.to_vector(), before);  // f32 -> f64 is exact
  net.to(DType::f32);
  EXPECT_EQ(net.conv1->weight.dtype(), DType::f32);
  EXPECT_EQ(net.bn1->num_batches_tracked.dtype(), DType::f64);  // a counter keeps f64
}

TEST(Module, LoadStateCopiesValuesAndConvertsDtype) {
  TinyNet a(1), b(2);
  EXPECT_NE(a.conv1->weight.to_vector(), b.conv1->weight.to_vector());
  TinyNet c(3, DType::f64);
  Tensor handle = b.conv1->weight;
  LoadStateReport r = b.load_state(a.state_dict());
  EXPECT_EQ(r.loaded, 13u);
  EXPECT_TRUE(r.missing.empty() && r.unexpected.empty());
  for (const auto& [n, t] : a.state_dict()) {
    EXPECT_EQ(b.find_tensor(n).to_vector(), t.to_vector()) << n;
  }
  EXPECT_TRUE(handle.same(b.conv1->weight));  // copied into, not replaced
  c.load_state(a.state_dict());               // f32 -> f64
  EXPECT_EQ(c.conv1->weight.dtype(), DType::f64);
  EXPECT_EQ(c.conv1->weight.to_vector(), a.conv1->weight.to_vector());
}

TEST(Module, LoadStateErrorsListEveryOffendingName) {
  TinyNet net(1);
  auto state = TinyNet(2).state_dict();
  state.erase("fc.bias");
  state.erase("bn1.running_mean");
  state["extra.weight"] = Tensor::zeros({1});
  state["conv1.weight"] = Tensor::zeros({4, 3, 1, 1});
  std::string msg = error_of([&] { net.load_state(state, true); }, ErrorCategory::invalid_argument);
  EXPECT_TRUE(contains(msg, "missing: fc.bias, bn1.running_mean")) << msg;
  EXPECT_TRUE(contains(msg, "unexpected: extra.weight")) << msg;
  EXPECT_TRUE(
      contains(msg, "shape mismatch: conv1.weight (module [4, 3, 3, 3], given [4, 3, 1, 1])"))
      << msg;

  // Not strict: missing / unexpected are reported, a shape mismatch is still an error.
  error_of([&] { net.load_state(state, false); }, ErrorCategory::invalid_argument);
  state.erase("conv1.weight");
  std::vector<double> kept = net.fc->bias.to_vector();
  LoadStateReport r = net.load_state(state, false);
  EXPECT_EQ(r.missing, (std::vector<std::string>{"conv1.weight", "fc.bias", "bn1.running_mean"}));
  EXPECT_EQ(r.unexpected, std::vector<std::string>{"extra.weight"});
  EXPECT_EQ(net.fc->bias.to_vector(), kept);
  EXPECT_EQ(net.fc->weight.to_vector(), state.at("fc.weight").to_vector());
}

TEST(Module, WeightsFileRoundTripAndMismatchNamesFileAndTensor) {
  test::TempDir dir;
  TinyNet a(1), b(2);
  save_weights(a, dir / "tiny.cvdw", "tiny_net", {{"width", 1}});
  CvdwReader r(dir / "tiny.cvdw");
  EXPECT_EQ(r.header().model, "tiny_net");
  EXPECT_EQ(r.entry("conv1.weight").kind, "parameter");
  EXPECT_EQ(r.entry("bn1.running_var").kind, "buffer");
  load_weights(b, dir / "tiny.cvdw");
  for (const auto& [n, t] : a.state_dict()) {
    EXPECT_EQ(b.find_tensor(n).to_vector(), t.to_vector()) << n;
  }
  Sequential other{std::make_shared<ReLU>()};
  std::string msg =
      error_of([&] { load_weights(other, dir / "tiny.cvdw"); }, ErrorCategory::format);
  EXPECT_TRUE(contains(msg, "tiny.cvdw")) << msg;
  EXPECT_TRUE(contains(msg, "unexpected: bn1.bias")) << msg;
}

TEST(Layers, DefaultInitialisationIsSeededKaimingUniform) {
  Generator g1(11), g2(11), g3(12);
  Conv2d a(Conv2dOptions(6, 8, 3, 2).with_groups(2), g1);
  Conv2d b(Conv2dOptions(6, 8, 3, 2).with_groups(2), g2);
  Conv2d c(Conv2dOptions(6, 8, 3, 2).with_groups(2), g3);
  EXPECT_EQ(a.weight.to_vector(), b.weight.to_vector());
  EXPECT_NE(a.weight.to_vector(), c.weight.to_vector());
  // fan_in = 6 / 2 * 3 * 2 = 18: weight and bias ~ U(-1/sqrt(18), 1/sqrt(18)).
  const double bound = 1.0 / std::sqrt(18.0);
  for (const Tensor& t : {a.weight, a.bias}) {
    double max_abs = 0;
    for (double v : t.to_vector()) {
      EXPECT_LE(std::abs(v), bound);
      max_abs = std::max(max_abs, std::abs(v));
    }
    EXPECT_GT(max_abs, 0.5 * bound);
  }
  // ConvTranspose2d: fan_in from weight.size(1) = out / groups (PyTorch).
  ConvTranspose2d t(ConvTranspose2dOptions(4, 6, 3), g1);
  EXPECT_EQ(t.weight.shape(), (Shape{4, 6, 3, 3}));
  for (double v : t.weight.to_vector()) EXPECT_LE(std::abs(v), 1.0 / std::sqrt(54.0));
  Linear l(5, 3, g1);
  for (double v : l.weight.to_vector()) EXPECT_LE(std::abs(v), 1.0 / std::sqrt(5.0));
  BatchNorm2d bn(BatchNorm2dOptions(3));
  EXPECT_EQ(bn.weight.to_vector(), (std::vector<double>{1, 1, 1}));
  EXPECT_EQ(bn.bias.to_vector(), (std::vector<double>{0, 0, 0}));
}

TEST(Layers, ConvOutputShapesWithAsymmetricPaddingAndOutputPadding) {
  Generator gen(1);
  // TF-"SAME" style k3s2: no padding top/left, 1 bottom/right.
  Conv2d conv(Conv2dOptions(1, 1, 3).with_stride(2).with_padding(0, 1, 0, 1).with_bias(false), gen,
              DType::f64);
  conv.weight.fill_(1.0);
  Tensor y = conv.forward(Tensor::ones({1, 1, 6, 6}, DType::f64));
  ASSERT_EQ(y.shape(), (Shape{1, 1, 3, 3}));
  std::vector<double> v = y.to_vector();
  EXPECT_DOUBLE_EQ(v[0], 9.0);  // window rows 0..2, cols 0..2
  EXPECT_DOUBLE_EQ(v[8], 4.0);  // window rows 4..6, cols 4..6: row / col 6 are padding
  ConvTranspose2d up(
      ConvTranspose2dOptions(2, 3, 3).with_stride(2).with_padding(1).with_output_padding(1), gen);
  EXPECT_EQ(up.forward(Tensor::zeros({1, 2, 3, 5})).shape(), (Shape{1, 3, 6, 10}));
  EXPECT_TRUE(contains(error_of(
                           [&] {
                             conv.forward(Tensor::zeros({1, 2, 6, 6}, DType::f64));
                           },
                           ErrorCategory::invalid_argument),
                       "expected 1 input channels"));
}

// x [2, 2, 2, 2]: channel 0 holds 1..8, channel 1 holds 2, 4, ..., 16 (over n, h, w).
Tensor bn_input(double shift = 0.0) {
  std::vector<double> v = {1, 2, 3, 4, 2, 4, 6, 8, 5, 6, 7, 8, 10, 12, 14, 16};
  for (double& x : v) x += shift;
  return Tensor::from_vector(v, {2, 2, 2, 2}, DType::f64);
}

TEST(Layers, BatchNormTrainUpdatesRunningStatsLikePyTorch) {
  BatchNorm2d bn(BatchNorm2dOptions(2), DType::f64);
  bn.weight.copy_(Tensor::from_vector(std::vector<double>{2.0, 0.5}, {2}, DType::f64));
  bn.bias.copy_(Tensor::from_vector(std::vector<double>{1.0, -1.0}, {2}, DType::f64));
  Tensor y = bn.forward(bn_input());
  // Channel 0: mean 4.5, biased var 5.25, unbiased 6. Channel 1: mean 9, biased 21, unbiased 24.
  const double eps = 1e-5;
  std::vector<double> yv = y.to_vector();
  EXPECT_NEAR(yv[0], 2.0 * (1 - 4.5) / std::sqrt(5.25 + eps) + 1.0, 1e-12);
  EXPECT_NEAR(yv[15], 0.5 * (16 - 9) / std::sqrt(21 + eps) - 1.0, 1e-12);
  std::vector<double> rm = bn.running_mean.to_vector(), rv = bn.running_var.to_vector();
  EXPECT_NEAR(rm[0], 0.1 * 4.5, 1e-14);
  EXPECT_NEAR(rm[1], 0.1 * 9, 1e-14);
  EXPECT_NEAR(rv[0], 0.9 + 0.1 * 6, 1e-14);
  EXPECT_NEAR(rv[1], 0.9 + 0.1 * 24, 1e-14);
  EXPECT_EQ(bn.num_batches_tracked.item(), 1.0);
  bn.forward(bn_input());
  EXPECT_NEAR(bn.running_mean.to_vector()[0], 0.9 * 0.45 + 0.1 * 4.5, 1e-14);
  EXPECT_EQ(bn.num_batches_tracked.item(), 2.0);

  // Eval: running statistics, no update, no count.
  bn.eval();
  rm = bn.running_mean.to_vector();
  rv = bn.running_var.to_vector();
  yv = bn.forward(bn_input()).to_vector();
  EXPECT_NEAR(yv[0], 2.0 * (1 - rm[0]) / std::sqrt(rv[0] + eps) + 1.0, 1e-12);
  EXPECT_EQ(bn.running_mean.to_vector(), rm);
  EXPECT_EQ(bn.num_batches_tracked.item(), 2.0);
}

TEST(Layers, BatchNormCumulativeAverageAndNoTracking) {
  // momentum None: running stats are the plain average over batches.
  BatchNorm2d cma(BatchNorm2dOptions(2).with_momentum(std::nullopt).with_affine(false), DType::f64);
  cma.forward(bn_input());
  cma.forward(bn_input(10.0));
  EXPECT_NEAR(cma.running_mean.to_vector()[0], (4.5 + 14.5) / 2, 1e-12);
  EXPECT_NEAR(cma.running_var.to_vector()[1], 24.0, 1e-12);
  EXPECT_EQ(cma.named_parameters().size(), 0u);

  BatchNorm2d batch_only(BatchNorm2dOptions(2).with_track_running_stats(false), DType::f64);
  EXPECT_EQ(batch_only.named_buffers().size(), 0u);
  batch_only.eval();  // still batch statistics
  std::vector<double> yv = batch_only.forward(bn_input()).to_vector();
  EXPECT_NEAR(yv[0], (1 - 4.5) / std::sqrt(5.25 + 1e-5), 1e-12);
  // One value per channel cannot be normalised in training (PyTorch raises too).
  BatchNorm2d bn(BatchNorm2dOptions(2));
  error_of([&] { bn.forward(Tensor::ones({1, 2, 1, 1})); }, ErrorCategory::invalid_argument);
}

TEST(Layers, SequentialChainsItsChildren) {
  Generator gen(0);
  auto l1 = std::make_shared<Linear>(2, 3, gen, true, DType::f64);
  auto l2 = std::make_shared<Linear>(3, 1, gen, false, DType::f64);
  Sequential seq{l1, std::make_shared<ReLU>(), l2, std::make_shared<Tanh>()};
  EXPECT_EQ(seq.size(), 4u);
  EXPECT_EQ(names_of(seq.named_parameters()),
            (std::vector<std::string>{"0.weight", "0.bias", "2.weight"}));
  l1->weight.copy_(Tensor::from_vector(std::vector<double>{1, 0, 0, 1, 1, -1}, {3, 2}, DType::f64));
  l1->bias.copy_(Tensor::from_vector(std::vector<double>{0, 0.5, -4}, {3}, DType::f64));
  l2->weight.copy_(Tensor::from_vector(std::vector<double>{0.5, -0.25, 2}, {1, 3}, DType::f64));
  Tensor x = Tensor::from_vector(std::vector<double>{1, 2, -3, 0.5}, {2, 2}, DType::f64);
  // Row (1, 2): h = relu(1, 2.5, -5) = (1, 2.5, 0); out = tanh(0.5 - 0.625).
  // Row (-3, 0.5): h = relu(-3, 1, -7.5) = (0, 1, 0); out = tanh(-0.25).
  std::vector<double> y = seq.forward(x).to_vector();
  ASSERT_EQ(y.size(), 2u);
  EXPECT_NEAR(y[0], std::tanh(0.5 - 0.625), 1e-14);
  EXPECT_NEAR(y[1], std::tanh(-0.25), 1e-14);

  // Activations one by one.
  Tensor a = Tensor::from_vector(std::vector<double>{-2, 0.5, 7}, {3}, DType::f64);
  EXPECT_EQ(ReLU6().forward(a).to_vector(), (std::vector<double>{0, 0.5, 6}));
  EXPECT_EQ(LeakyReLU(0.1).forward(a).to_vector()[0], -0.2);
  EXPECT_NEAR(Sigmoid().forward(a).to_vector()[1], 1 / (1 + std::exp(-0.5)), 1e-15);
  EXPECT_TRUE(contains(seq.repr(), "(0): Linear(in_features=2, out_features=3, bias=True)"));
  error_of([&] { Module().forward(a); }, ErrorCategory::unsupported);
}

}  // namespace
}  // namespace cvd
