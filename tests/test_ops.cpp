// The op table (tests/op_case_table.cpp) run four ways, like ggml's test-backend-ops:
//  - GradCheck: in float64, the autograd gradient of sum(op(x) * R) against central finite
//    differences, for every differentiable input element;
//  - F32VsReference: the fast f32 kernels (forward and backward) against the float64 reference
//    kernels on the same inputs (tests/op_case_run.h; test_cuda_ops runs the same on CUDA);
//  - F32StridedInputsVsReference: the same with non-contiguous input views;
//  - Bf16VsReference: the same in the CPU's bf16 arithmetic, where the CPU has it natively.
// Plus coverage: every op of the dispatch table has a reference kernel and a fast CPU kernel.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "engine/autograd.h"
#include "engine/compute_precision.h"
#include "engine/dispatch.h"
#include "engine/random.h"
#include "tests/op_case_run.h"

namespace cvd::test {
namespace {

struct Prepared {
  std::vector<Tensor> inputs;  // f64 leaves
  Tensor weights;              // R of the loss sum(out * R), f64
};

Prepared prepare(const OpCase& c, uint64_t seed) {
  Prepared p;
  p.inputs = make_case_inputs(c, seed);
  Generator g(seed + 1);
  Tensor out;
  {
    NoGradGuard ng;
    out = c.fn(p.inputs);
  }
  p.weights = Tensor::randn(out.shape(), g, DType::f64);
  return p;
}

Tensor weighted_loss(const OpCase& c, const std::vector<Tensor>& in, const Tensor& w) {
  return sum(mul(c.fn(in), w));
}

class OpTable : public ::testing::TestWithParam<OpCase> {};

TEST_P(OpTable, GradCheck) {
  const OpCase& c = GetParam();
  Prepared p = prepare(c, 1234);
  Tensor loss = weighted_loss(c, p.inputs, p.weights);
  std::vector<Tensor> diff;
  for (auto& t : p.inputs)
    if (t.requires_grad()) diff.push_back(t);
  std::vector<Tensor> analytic = grad(loss, diff);
  const double eps = 1e-6;
  NoGradGuard ng;
  for (size_t i = 0; i < diff.size(); ++i) {
    double* x = diff[i].data<double>();
    std::vector<double> a = analytic[i].to_vector();
    ASSERT_EQ(static_cast<int64_t>(a.size()), diff[i].numel());
    for (int64_t k = 0; k < diff[i].numel(); ++k) {
      double orig = x[k];
      x[k] = orig + eps;
      double lp = weighted_loss(c, p.inputs, p.weights).item();
      x[k] = orig - eps;
      double lm = weighted_loss(c, p.inputs, p.weights).item();
      x[k] = orig;
      double numeric = (lp - lm) / (2 * eps);
      ASSERT_NEAR(a[k], numeric, 1e-6 + 1e-5 * std::abs(numeric))
          << c.name << ": input " << i << " element " << k;
    }
  }
}

TEST_P(OpTable, F32VsReference) {
  EXPECT_EQ(compare_with_reference(GetParam(), DeviceId::cpu(), 99), "");
}

// The same with every f32 input a non-contiguous view (transposed storage or a narrowed row).
TEST_P(OpTable, F32StridedInputsVsReference) {
  CompareOptions o;
  o.strided_inputs = true;
  EXPECT_EQ(compare_with_reference(GetParam(), DeviceId::cpu(), 99, o), "");
}

// The CPU's bf16 arithmetic (engine/compute_precision.h: convolutions on AVX512-BF16 / AMX, every
// other op f32) as a backend of the table: every case within 2% of the float64 reference
// (relative to max(1, |ref|max); gradients 8%), and the cases sized for it provably on the bf16
// path (their output differs from the f32 run's).
TEST_P(OpTable, Bf16VsReference) {
  std::string why;
  if (!bf16_supported(&why)) GTEST_SKIP() << "no native bf16 on this CPU: " << why;
  const OpCase& c = GetParam();
  const std::vector<double> f32 = run_case_f32(c, DeviceId::cpu(), 99);
  ScopedComputePrecision bf16(ComputePrecision::bf16);
  CompareOptions o;
  o.min_tol = 2e-2;
  EXPECT_EQ(compare_with_reference(c, DeviceId::cpu(), 99, o), "");
  // The cases named *_c16 are sized for the bf16 path (16+ channels per group).
  if (c.name.size() > 4 && c.name.compare(c.name.size() - 4, 4, "_c16") == 0) {
    EXPECT_NE(run_case_f32(c, DeviceId::cpu(), 99), f32)
        << c.name << ": the bf16 run gave the f32 run's output bit for bit";
  }
}

INSTANTIATE_TEST_SUITE_P(Ops, OpTable, ::testing::ValuesIn(all_op_cases()),
                         [](const ::testing::TestParamInfo<OpCase>& i) { return i.param.name; });

TEST(KernelCoverage, EveryOpHasReferenceAndCpuKernels) {
  const KernelRegistry& r = kernel_registry();
  for (int i = 0; i < kNumOps; ++i) {
    OpId op = static_cast<OpId>(i);
    EXPECT_TRUE(r.has(op, DeviceType::cpu, DType::f64))
        << "no reference kernel for " << op_name(op);
    EXPECT_TRUE(r.has(op, DeviceType::cpu, DType::f32)) << "no fast CPU kernel for " << op_name(op);
  }
}

TEST(Autograd, AccumulatesAndFreesGraph) {
  Tensor x = Tensor::from_vector(std::vector<double>{1, 2, 3}, {3}, DType::f64).requires_grad_();
  Tensor y = sum(mul(x, x));
  y.backward();
  EXPECT_EQ(x.grad().to_vector(), (std::vector<double>{2, 4, 6}));
  // A second backward through the freed graph is a clear error.
  EXPECT_THROW(y.backward(), Error);
  // Gradients accumulate across backward calls.
  sum(mul_scalar(x, 3.0)).backward();
  EXPECT_EQ(x.grad().to_vector(), (std::vector<double>{5, 7, 9}));
  x.zero_grad();
  EXPECT_FALSE(x.grad().defined());
}

TEST(Autograd, NoGradGuardRecordsNothing) {
  Tensor x = Tensor::ones({2, 2}, DType::f64).requires_grad_();
  NoGradGuard ng;
  Tensor y = mul(x, x);
  EXPECT_FALSE(y.requires_grad());
  EXPECT_EQ(y.grad_fn(), nullptr);
}

TEST(Autograd, DiamondGraphSumsBothPaths) {
  // y = a*b + a, with a used twice: dy/da = b + 1.
  Tensor a = Tensor::from_vector(std::vector<double>{2}, {1}, DType::f64).requires_grad_();
  Tensor b = Tensor::from_vector(std::vector<double>{5}, {1}, DType::f64).requires_grad_();
  Tensor y = sum(add(mul(a, b), a));
  auto g = grad(y, {a, b});
  EXPECT_DOUBLE_EQ(g[0].item(), 6.0);
  EXPECT_DOUBLE_EQ(g[1].item(), 2.0);
}

TEST(Autograd, UnusedBranchDoesNotBlockOthers) {
  // Comparisons produce no gradient; the path through x must still be reached.
  Tensor x = Tensor::from_vector(std::vector<double>{1, -2}, {2}, DType::f64).requires_grad_();
  Tensor m = gt(x, Tensor::zeros({}, DType::f64));
  Tensor y = sum(where(m, x, mul_scalar(x, 0.5)));
  y.backward();
  EXPECT_EQ(x.grad().to_vector(), (std::vector<double>{1.0, 0.5}));
}

TEST(Tensor, ViewsShareStorageAndBroadcastErrorsAreClear) {
  Tensor x = Tensor::zeros({2, 3});
  Tensor v = x.narrow(1, 1, 2);
  EXPECT_FALSE(v.is_contiguous());
  EXPECT_EQ(v.storage(), x.storage());
  EXPECT_THROW(add(Tensor::zeros({2, 3}), Tensor::zeros({4})), Error);
  EXPECT_THROW(Tensor::zeros({2}).reshape({3}), Error);
  try {
    conv2d(Tensor::zeros({1, 3, 4, 4}), Tensor::zeros({2, 4, 3, 3}), Tensor(), Conv2dParams{});
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("does not match weight"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace cvd::test
