// The batch norm, pooling and matmul CPU kernels (kernels/cpu: hand-written and oneDNN-backed)
// against the float64 reference kernels. Harness and tolerances: tests/kernel_pair_test.h.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "engine/dispatch.h"
#include "engine/kernel_params.h"
#include "engine/random.h"
#include "engine/tensor.h"
#include "tests/kernel_pair_test.h"
#include "tests/test_support.h"

namespace cvd {
namespace {

using namespace kernel_pair_test;

// ---- Batch norm ------------------------------------------------------------------------------
// Hand-written since oneDNN 2.6 has only a slow C++ path on NCHW (kernels/cpu/cpu_batch_norm.cpp,
// impl "openmp"); tested here, with this file's harness and tolerances, as it replaced oneDNN's.

struct BnCase {
  Shape shape;
  bool training, gamma, beta;
  int act;  // 0 none, 1 relu, 2 clip(-0.5, 1) fused (BatchNormParams::fused_act)
};

std::string bn_name(const BnCase& c) {
  static const char* acts[] = {"", " relu", " clip"};
  return shape_str(c.shape) + (c.training ? " train" : " eval") + (c.gamma ? " gamma" : "") +
         (c.beta ? " beta" : "") + acts[c.act];
}

TEST(CpuBatchNorm, ForwardBackwardAndRunningStatsMatchReference) {
  std::vector<BnCase> cases;
  // The last shape's planes span two of the backward's float-sum blocks.
  for (const Shape& s : {Shape{2, 3, 5, 7}, Shape{1, 4, 1, 3}, Shape{4, 20, 3, 3}, Shape{6, 5},
                         Shape{3, 4, 10}, Shape{2, 16, 24, 40}, Shape{2, 3, 70, 80}}) {
    for (int act = 0; act < 3; ++act) {
      for (bool training : {true, false}) {
        for (int affine = 0; affine < 4; ++affine) {
          cases.push_back({s, training, (affine & 1) != 0, (affine & 2) != 0, act});
        }
      }
    }
  }
  for (const BnCase& bc : cases) {
    SCOPED_TRACE(bn_name(bc));
    Generator gen(31);
    const int64_t c = bc.shape[1];
    BatchNormParams p;
    p.training = bc.training;
    p.momentum = 0.2;
    p.eps = 1e-3;
    p.fused_act = bc.act != 0;
    p.act = bc.act == 1 ? UnaryParams{UnaryOp::relu} : UnaryParams{UnaryOp::clip, -0.5, 1.0};
    Pair x = normal(bc.shape, gen, 2.0, 0.5);
    Pair gamma = bc.gamma ? uniform({c}, gen, 0.5, 1.5) : none();
    Pair beta = bc.beta ? normal({c}, gen) : none();
    Pair rmean = normal({c}, gen, 0.3), rvar = uniform({c}, gen, 0.5, 2.0);
    Pair y = outputs(bc.shape), mean = outputs({c}), invstd = outputs({c});
    run_both(OpId::batch_norm, {x, gamma, beta, rmean, rvar}, {y, mean, invstd}, &p, "openmp");
    expect_close(y, 1e-4, "y");
    expect_close(mean, 1e-4, "mean");
    expect_close(invstd, 1e-4, "invstd");
    expect_close(rmean, 1e-4, "running mean");
    expect_close(rvar, 1e-4, "running var");

    Pair gy = normal(bc.shape, gen);
    // All gradients, then each one alone (the others undefined).
    for (int wanted = 0; wanted < 4; ++wanted) {
      const bool want_gx = wanted == 0 || wanted == 1;
      const bool want_gg = bc.gamma && (wanted == 0 || wanted == 2);
      const bool want_gb = bc.beta && (wanted == 0 || wanted == 3);
      if (!want_gx && !want_gg && !want_gb) continue;
      Pair gx = want_gx ? outputs(bc.shape) : none();
      Pair gg = want_gg ? outputs({c}) : none(), gb = want_gb ? outputs({c}) : none();
      // The reference takes mean / invstd from its own forward; ours from its own.
      std::vector<Pair> in = {gy, x, gamma, mean, invstd};
      if (p.fused_act) in.push_back(beta);
      run_both(OpId::batch_norm_backward, in, {gx, gg, gb}, &p, "openmp");
      const double tol = sum_tolerance(x.t64.numel() / c);
      if (want_gx) expect_close(gx, tol, "gx");
      if (want_gg) expect_close(gg, tol, "ggamma");
      if (want_gb) expect_close(gb, tol, "gbeta");
    }
  }
}

TEST(CpuBatchNorm, TrainingUpdatesRunningStatsWithUnbiasedVariance) {
  // One channel holding {1, 3}: mean 2, biased var 1, unbiased var 2.
  Tensor x = Tensor::from_vector(std::vector<double>{1.0, 3.0}, {2, 1, 1, 1}, DType::f32);
  Tensor rm = Tensor::from_vector(std::vector<double>{0.0}, {1}, DType::f32);
  Tensor rv = Tensor::from_vector(std::vector<double>{1.0}, {1}, DType::f32);
  Tensor y = Tensor::empty({2, 1, 1, 1}), mean = Tensor::empty({1}), invstd = Tensor::empty({1});
  BatchNormParams p;
  p.momentum = 0.1;
  p.eps = 0.0;
  KernelArgs a{{x, Tensor(), Tensor(), rm, rv}, {y, mean, invstd}, &p};
  kernel(OpId::batch_norm, DType::f32).fn(a);
  EXPECT_NEAR(mean.item(), 2.0, 1e-6);
  EXPECT_NEAR(invstd.item(), 1.0, 1e-6);
  EXPECT_NEAR(rm.item(), 0.9 * 0.0 + 0.1 * 2.0, 1e-6);
  EXPECT_NEAR(rv.item(), 0.9 * 1.0 + 0.1 * 2.0, 1e-6);
  EXPECT_NEAR(y.to_vector()[0], -1.0, 1e-6);
  EXPECT_NEAR(y.to_vector()[1], 1.0, 1e-6);
}

// ---- Pooling -----------------------------------------------------------------------------------

struct PoolCase {
  const char* name;
  int64_t n, c, h, w;
  Pool2dParams p;
};

Pool2dParams pool_params(int k, int s, int pt, int pb, int pl, int pr, bool ceil, bool include) {
  Pool2dParams p;
  p.kernel_h = p.kernel_w = k;
  p.stride_h = p.stride_w = s;
  p.pad_top = pt, p.pad_bottom = pb, p.pad_left = pl, p.pad_right = pr;
  p.ceil_mode = ceil;
  p.count_include_pad = include;
  return p;
}

// PyTorch's pooling output size (as engine/ops_nn.cpp).
int64_t pool_out(int64_t in, int k, int s, int pb, int pa, bool ceil_mode) {
  const int64_t span = in + pb + pa - k;
  int64_t out = (ceil_mode ? (span + s - 1) / s : span / s) + 1;
  if (ceil_mode && (out - 1) * s >= in + pb) --out;
  return out;
}

TEST(OnednnPool, MaxAndAvgForwardBackwardMatchReference) {
  const std::vector<PoolCase> cases = {
      {"k2 s2", 2, 3, 6, 8, pool_params(2, 2, 0, 0, 0, 0, false, true)},
      {"k2 s2 odd floor", 2, 3, 7, 9, pool_params(2, 2, 0, 0, 0, 0, false, true)},
      {"k2 s2 odd ceil", 2, 3, 7, 9, pool_params(2, 2, 0, 0, 0, 0, true, true)},
      {"k3 s2 p1", 1, 4, 9, 10, pool_params(3, 2, 1, 1, 1, 1, false, true)},
      {"k3 s2 p1 ceil include pad", 2, 2, 8, 6, pool_params(3, 2, 1, 1, 1, 1, true, true)},
      {"k3 s2 p1 ceil exclude pad", 2, 2, 8, 6, pool_params(3, 2, 1, 1, 1, 1, true, false)},
      {"k3 s2 p0 ceil include pad", 1, 3, 6, 8, pool_params(3, 2, 0, 0, 0, 0, true, true)},
      {"k3 s1 p1 exclude pad", 2, 3, 5, 5, pool_params(3, 1, 1, 1, 1, 1, false, false)},
      {"k3 s3 asym pads", 1, 3, 8, 7, pool_params(3, 3, 0, 1, 1, 0, false, true)},
      {"k3 s3 asym pads ceil", 1, 3, 8, 7, pool_params(3, 3, 0, 1, 1, 0, true, true)},
      {"1x1 image k1", 2, 5, 1, 1, pool_params(1, 1, 0, 0, 0, 0, false, true)},
      {"k2 s1 overlapping", 2, 3, 5, 6, pool_params(2, 1, 0, 0, 0, 0, false, true)},
      {"blocked channels", 2, 32, 9, 7, pool_params(3, 2, 1, 1, 1, 1, true, false)},
  };
  for (const PoolCase& pc : cases) {
    SCOPED_TRACE(pc.name);
    Generator gen(41);
    const Pool2dParams& p = pc.p;
    const int64_t oh = pool_out(pc.h, p.kernel_h, p.stride_h, p.pad_top, p.pad_bottom, p.ceil_mode);
    const int64_t ow = pool_out(pc.w, p.kernel_w, p.stride_w, p.pad_left, p.pad_right, p.ceil_mode);
    const Shape xs = {pc.n, pc.c, pc.h, pc.w}, ys = {pc.n, pc.c, oh, ow};
    Pair x = normal(xs, gen), gy = normal(ys, gen);
    // Repeated values make ties, where the first maximum must win.
    std::vector<double> tied = x.t64.to_vector();
    for (size_t i = 0; i < tied.size(); i += 3) tied[i] = std::round(tied[i]);
    Pair xt = make_pair(tied, xs);
    for (const Pair* input : {&x, &xt}) {
      Pair y = outputs(ys);
      run_both(OpId::max_pool2d, {*input}, {y}, &p);
      expect_close(y, 1e-5, "max_pool2d");
      Pair gx = outputs(xs);
      run_both(OpId::max_pool2d_backward, {gy, *input}, {gx}, &p);
      expect_close(gx, 1e-5, "max_pool2d_backward");
    }
    Pair ya = outputs(ys);
    run_both(OpId::avg_pool2d, {x}, {ya}, &p);
    expect_close(ya, 1e-5, "avg_pool2d");
    Pair gxa = outputs(xs);
    run_both(OpId::avg_pool2d_backward, {gy}, {gxa}, &p);
    expect_close(gxa, 1e-5, "avg_pool2d_backward");
  }
}

// ---- Matmul ------------------------------------------------------------------------------------

TEST(OnednnMatmul, TransposesAndBatchBroadcastMatchReference) {
  struct MatmulCase {
    int64_t batch, m, k, n, b_batch;
  };
  const std::vector<MatmulCase> cases = {
      {1, 5, 7, 3, 1}, {3, 4, 6, 5, 3},   {4, 3, 8, 9, 1},
      {2, 1, 5, 1, 2}, {1, 17, 1, 13, 1}, {2, 33, 40, 18, 1},
  };
  for (const MatmulCase& mc : cases) {
    for (int t = 0; t < 4; ++t) {
      MatmulParams p;
      p.trans_a = (t & 1) != 0;
      p.trans_b = (t & 2) != 0;
      SCOPED_TRACE(std::to_string(mc.batch) + "x" + std::to_string(mc.m) + "x" +
                   std::to_string(mc.k) + "x" + std::to_string(mc.n) + " b batch " +
                   std::to_string(mc.b_batch) + " trans " + std::to_string(t));
      Generator gen(53);
      Pair a = normal(p.trans_a ? Shape{mc.batch, mc.k, mc.m} : Shape{mc.batch, mc.m, mc.k}, gen);
      Pair b =
          normal(p.trans_b ? Shape{mc.b_batch, mc.n, mc.k} : Shape{mc.b_batch, mc.k, mc.n}, gen);
      Pair c = outputs({mc.batch, mc.m, mc.n});
      run_both(OpId::matmul, {a, b}, {c}, &p);
      expect_close(c, 1e-4, "matmul");
    }
  }
}

}  // namespace
}  // namespace cvd
