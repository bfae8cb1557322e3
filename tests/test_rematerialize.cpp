// Rematerialization (engine/rematerialize.h): batch_norm_act's output is not kept for backward,
// neither by the op itself nor by a convolution that reads it, and the gradients are those of the
// unfused batch_norm -> relu -> conv. (Finite-difference checks: the batch_norm_*act* rows of
// tests/op_case_table.cpp.)
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>

#include "engine/autograd.h"
#include "engine/layers.h"
#include "engine/ops.h"
#include "engine/rematerialize.h"
#include "engine/storage.h"

namespace cvd {
namespace {

// Restores the process-wide switch at the end of a test.
class RematerializationScope {
 public:
  explicit RematerializationScope(bool on) : prev_(rematerialization_enabled()) {
    set_rematerialization(on);
  }
  ~RematerializationScope() { set_rematerialization(prev_); }

 private:
  bool prev_;
};

struct Leaves {
  Tensor x, gamma, beta, w;
};

Leaves make_leaves(uint64_t seed) {
  Generator gen(seed);
  Leaves l{Tensor::randn({2, 5, 6, 7}, gen), Tensor::uniform({5}, gen, 0.5, 2.0),
           Tensor::randn({5}, gen), Tensor::randn({3, 5, 3, 3}, gen, DType::f32, 0.3)};
  for (Tensor* t : {&l.x, &l.gamma, &l.beta, &l.w}) t->requires_grad_();
  return l;
}

Conv2dParams same3x3() {
  Conv2dParams p;
  p.pad_top = p.pad_bottom = p.pad_left = p.pad_right = 1;
  return p;
}

const BatchNormParams kTrain{};  // training, momentum 0.1, eps 1e-5

// Whether the activation between the batch norm and the convolution is still alive once the
// caller drops its own handle (i.e. whether backward keeps it).
bool activation_kept_for_backward(const Leaves& l, Tensor* out) {
  Tensor rm = Tensor::zeros({5}), rv = Tensor::ones({5});
  Tensor z = batch_norm_act(l.x, rm, rv, l.gamma, l.beta, kTrain, {UnaryOp::relu});
  std::weak_ptr<Storage> zs = z.storage();
  *out = conv2d(z, l.w, Tensor(), same3x3());
  z = Tensor();
  return !zs.expired();
}

TEST(Rematerialize, ConvolutionRecomputesInsteadOfKeepingTheActivation) {
  Leaves l = make_leaves(7);
  Tensor y;
  {
    RematerializationScope on(true);
    EXPECT_FALSE(activation_kept_for_backward(l, &y));
  }
  {
    RematerializationScope off(false);
    Tensor y_off;
    EXPECT_TRUE(activation_kept_for_backward(l, &y_off));
  }
}

// The fused op with rematerialization on and off, and the unfused ops: same output and gradients
// (f32; the recomputed activation comes from the eval-mode kernel, not bit-identical).
TEST(Rematerialize, GradientsMatchTheUnfusedOps) {
  Leaves l = make_leaves(11);
  Generator gen(3);
  const Tensor weights = Tensor::randn({2, 3, 6, 7}, gen);
  auto run = [&](int mode) {
    RematerializationScope scope(mode != 0);
    Tensor rm = Tensor::zeros({5}), rv = Tensor::ones({5});
    Tensor z =
        mode == 2 ? relu6(batch_norm(l.x, rm, rv, l.gamma, l.beta, kTrain))
                  : batch_norm_act(l.x, rm, rv, l.gamma, l.beta, kTrain, {UnaryOp::clip, 0.0, 6.0});
    Tensor y = conv2d(mul_scalar(z, 1.0) /* a second reader */, l.w, Tensor(), same3x3());
    Tensor loss = add(sum(mul(y, weights)), sum(mul(conv2d(z, l.w, Tensor(), same3x3()), y)));
    std::vector<Tensor> g = grad(loss, {l.x, l.gamma, l.beta, l.w});
    g.push_back(y.detach());
    g.push_back(rm);
    g.push_back(rv);
    return g;
  };
  const auto unfused = run(2), fused_on = run(1), fused_off = run(0);
  const char* names[] = {"x", "gamma", "beta", "w", "output", "running mean", "running var"};
  for (size_t i = 0; i < unfused.size(); ++i) {
    const auto a = unfused[i].to_vector(), b = fused_on[i].to_vector(),
               c = fused_off[i].to_vector();
    ASSERT_EQ(a.size(), b.size());
    double scale = 1.0;
    for (double v : a) scale = std::max(scale, std::abs(v));
    for (size_t k = 0; k < a.size(); ++k) {
      ASSERT_NEAR(b[k], a[k], 2e-5 * scale) << names[i] << " element " << k << " (recomputed)";
      ASSERT_NEAR(c[k], a[k], 2e-5 * scale) << names[i] << " element " << k << " (kept)";
    }
  }
}

// A tensor changed in place after the op (its storage version moved) is kept, not recomputed:
// the recipe would give the old values.
TEST(Rematerialize, ModifiedActivationIsKept) {
  RematerializationScope on(true);
  Leaves l = make_leaves(5);
  Tensor rm = Tensor::zeros({5}), rv = Tensor::ones({5});
  Tensor z = batch_norm_act(l.x, rm, rv, l.gamma, l.beta, kTrain, {UnaryOp::relu});
  z.bump_version();
  EXPECT_FALSE(SavedTensor(z).rematerialized());
  std::weak_ptr<Storage> zs = z.storage();
  Tensor y = conv2d(z, l.w, Tensor(), same3x3());
  z = Tensor();
  EXPECT_FALSE(zs.expired());
}

// Sequential runs BatchNorm2d + ReLU as one batch_norm_act: same output, gradients and running
// statistics as the modules one by one.
TEST(Rematerialize, SequentialFusesBatchNormAndRelu) {
  auto build = [] {
    Generator gen(21);
    auto s = std::make_shared<Sequential>();
    s->push_back(std::make_shared<Conv2d>(Conv2dOptions(3, 4, 3).with_padding(1), gen));
    s->push_back(std::make_shared<BatchNorm2d>(BatchNorm2dOptions(4)));
    s->push_back(std::make_shared<ReLU>());
    s->push_back(std::make_shared<Conv2d>(Conv2dOptions(4, 2, 1), gen));
    return s;
  };
  auto fused = build(), plain = build();
  Generator gen(4);
  Tensor x = Tensor::randn({2, 3, 5, 6}, gen);
  Tensor y_fused = fused->forward(x);
  Tensor h = (*plain)[0]->forward(x);
  h = (*plain)[2]->forward((*plain)[1]->forward(h));
  Tensor y_plain = (*plain)[3]->forward(h);
  sum(square(y_fused)).backward();
  sum(square(y_plain)).backward();
  auto near = [](const Tensor& a, const Tensor& b, const char* what) {
    const auto va = a.to_vector(), vb = b.to_vector();
    ASSERT_EQ(va.size(), vb.size()) << what;
    for (size_t k = 0; k < va.size(); ++k)
      ASSERT_NEAR(va[k], vb[k], 1e-5 * std::max(1.0, std::abs(vb[k]))) << what << " " << k;
  };
  near(y_fused, y_plain, "output");
  auto* bf = dynamic_cast<BatchNorm2d*>((*fused)[1].get());
  auto* bp = dynamic_cast<BatchNorm2d*>((*plain)[1].get());
  near(bf->running_mean, bp->running_mean, "running mean");
  near(bf->running_var, bp->running_var, "running var");
  near(bf->weight.grad(), bp->weight.grad(), "gamma grad");
  auto* cf = dynamic_cast<Conv2d*>((*fused)[0].get());
  auto* cp = dynamic_cast<Conv2d*>((*plain)[0].get());
  near(cf->weight.grad(), cp->weight.grad(), "first conv weight grad");
}

}  // namespace
}  // namespace cvd
