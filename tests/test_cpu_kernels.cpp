// The OpenMP f32 CPU kernels (kernels/cpu, impl "openmp") of the element-wise, reduction,
// layout and optimiser ops against the float64 reference kernels (kernels/reference), both called
// through the dispatch registry on the same inputs (tests/cpu_kernel_comparison.h). The resize and
// grid_sample kernels are in test_cpu_resample_kernels.cpp.
//
// Tolerances (max |fast - ref| <= tol * max |ref| over each output):
//   exact (0): copy, fill, concat, pad, where, comparisons;
//   1e-6: binary arithmetic, reduce_sum (double accumulation);
//   2e-6: unary, unary_backward (f32 transcendentals);
//   1e-5: adam, sgd.
#include <gtest/gtest.h>

#include <algorithm>
#include <functional>
#include <string>
#include <vector>

#include "engine/kernel_params.h"
#include "tests/cpu_kernel_comparison.h"

namespace cvd {
namespace {

using namespace cvd::test;  // NOLINT: the comparison helpers

// ---- copy / fill -----------------------------------------------------------------------------

TEST(CpuKernels, CopyFromAnyStridesToF32AndF64) {
  Generator gen(1);
  struct Case {
    std::string name;
    Pair src;
  };
  const Pair big = normal({6, 40, 50}, gen);
  std::vector<Case> cases = {
      {"contiguous", normal({3, 5, 7}, gen)},
      {"large contiguous", normal({4, 64, 33, 41}, gen)},
      {"permuted nchw->nhwc", permuted({2, 3, 4, 5}, {0, 2, 3, 1}, gen)},
      {"transposed large", permuted({300, 257}, {1, 0}, gen)},
      {"row broadcast", broadcast(normal({5}, gen), {4, 5})},
      {"column broadcast", broadcast(normal({4, 1}, gen), {4, 6})},
      {"scalar broadcast", broadcast(normal({}, gen), {3, 4})},
      {"narrowed", view(big, {6, 20, 30}, {2000, 50, 1}, 5 * 50 + 7)},
      {"zero-dim", normal({}, gen)},
      {"one element", normal({1, 1, 1}, gen)},
  };
  for (const Case& c : cases) {
    for (DType dst : {DType::f32, DType::f64}) {
      const Results r = run_both(OpId::copy, {c.src}, {c.src.t64.shape()}, nullptr, false, dst);
      expect_close(r, 0.0, "copy " + c.name + " to " + dtype_name(dst));
    }
  }
}

TEST(CpuKernels, FillWritesEveryElement) {
  for (const Shape& s : std::vector<Shape>{{}, {1}, {7, 3}, {3, 50, 1000}}) {
    const FillParams p{-2.75};
    expect_close(run_both(OpId::fill, {}, {s}, &p), 0.0, "fill " + shape_text(s));
  }
}

// ---- unary -----------------------------------------------------------------------------------

struct UnaryCase {
  UnaryOp op;
  double a, b;
  bool positive;  // domain x > 0 (log, sqrt, pow, reciprocal)
  const char* name;
};

const std::vector<UnaryCase> kUnaryCases = {
    {UnaryOp::relu, 0, 0, false, "relu"},
    // Bounds exact in f32: clip's backward reads the output (y strictly inside the bounds), and
    // this test hands both kernels the same f32-rounded y, which an inexact bound (0.7) would
    // put on different sides of the f64 and f32 bound.
    {UnaryOp::clip, -0.5, 0.75, false, "clip"},
    {UnaryOp::clip, 0.0, 6.0, false, "relu6"},
    {UnaryOp::leaky_relu, 0.1, 0, false, "leaky_relu"},
    {UnaryOp::sigmoid, 0, 0, false, "sigmoid"},
    {UnaryOp::tanh, 0, 0, false, "tanh"},
    {UnaryOp::exp, 0, 0, false, "exp"},
    {UnaryOp::log, 0, 0, true, "log"},
    {UnaryOp::abs, 0, 0, false, "abs"},
    {UnaryOp::sqrt, 0, 0, true, "sqrt"},
    {UnaryOp::neg, 0, 0, false, "neg"},
    {UnaryOp::reciprocal, 0, 0, true, "reciprocal"},
    {UnaryOp::pow_scalar, 1.7, 0, true, "pow_scalar"},
    {UnaryOp::mul_scalar, -3.5, 0, false, "mul_scalar"},
    {UnaryOp::add_scalar, 0.25, 0, false, "add_scalar"},
    {UnaryOp::gelu, 0, 0, false, "gelu"},
};

TEST(CpuKernels, UnaryForwardAndBackward) {
  Generator gen(2);
  for (const UnaryCase& u : kUnaryCases) {
    for (const Shape& s : std::vector<Shape>{{1}, {13}, {3, 7, 11}, {2, 16, 41, 47}}) {
      const std::string what = std::string(u.name) + " " + shape_text(s);
      const Pair x = u.positive ? uniform(s, gen, 0.1, 3.0) : normal(s, gen, 2.0);
      const UnaryParams p{u.op, u.a, u.b};
      const Results fwd = run_both(OpId::unary, {x}, {s}, &p);
      expect_close(fwd, 2e-6, what + " forward");
      // y as the reference computed it (rounded to f32 for both), gy random.
      const Pair y = pair_of(fwd.ref.at(0), s);
      const Pair gy = normal(s, gen);
      expect_close(run_both(OpId::unary_backward, {gy, x, y}, {s}, &p), 2e-6, what + " backward");
    }
  }
}

// ---- binary / where ----------------------------------------------------------------------------

// Values of a broadcasting op's input: normal, small integers (so that comparisons meet equal
// pairs) or positive in [0.5, 2] (divisors).
enum class Values { normal, integer, positive };

Pair values(const Shape& s, Generator& gen, Values kind) {
  switch (kind) {
    case Values::integer:
      return integers(s, gen, -2, 3);
    case Values::positive:
      return uniform(s, gen, 0.5, 2.0);
    default:
      return normal(s, gen);
  }
}

// Input layouts of a broadcasting op: a and b as views of `out`'s shape.
using InputMaker = std::function<Pair(Generator&, const Shape&, Values)>;
struct BroadcastCase {
  std::string name;
  Shape out;
  InputMaker a, b;
};

InputMaker bcast_from(Shape base) {
  return [base](Generator& gen, const Shape& out, Values kind) {
    return broadcast(values(base, gen, kind), out);
  };
}

InputMaker full_input() {
  return [](Generator& gen, const Shape& out, Values kind) { return values(out, gen, kind); };
}

InputMaker transposed_last_two() {
  return [](Generator& gen, const Shape& out, Values kind) {
    Shape stored = out;
    std::swap(stored[stored.size() - 1], stored[stored.size() - 2]);
    const Pair base = values(stored, gen, kind);
    Shape strides = contiguous_strides(stored);
    std::swap(strides[strides.size() - 1], strides[strides.size() - 2]);
    return view(base, out, strides);
  };
}

std::vector<BroadcastCase> broadcast_cases() {
  return {
      {"same shape", {4, 5, 6}, full_input(), full_input()},
      {"scalar b", {4, 5, 6}, full_input(), bcast_from({})},
      {"scalar a", {4, 5, 6}, bcast_from({1}), full_input()},
      {"row", {4, 5, 6}, full_input(), bcast_from({6})},
      {"column", {4, 5, 6}, full_input(), bcast_from({4, 5, 1})},
      {"middle dim", {4, 5, 6}, full_input(), bcast_from({1, 5, 1})},
      {"channel bias", {2, 3, 7, 9}, full_input(), bcast_from({1, 3, 1, 1})},
      {"outer product", {4, 5, 6}, bcast_from({4, 1, 6}), bcast_from({1, 5, 1})},
      {"transposed a", {3, 8, 9}, transposed_last_two(), full_input()},
      {"transposed a, row b", {3, 8, 9}, transposed_last_two(), bcast_from({9})},
      {"one element", {1, 1}, full_input(), full_input()},
      {"large channel bias", {2, 64, 23, 29}, full_input(), bcast_from({1, 64, 1, 1})},
      {"large same shape", {2, 3, 150, 151}, full_input(), full_input()},
      {"large scalar", {1, 1, 300, 400}, full_input(), bcast_from({})},
      {"large column", {2, 1, 300, 200}, full_input(), bcast_from({2, 1, 300, 1})},
  };
}

TEST(CpuKernels, BinaryWithBroadcasting) {
  Generator gen(3);
  const std::vector<std::pair<BinaryOp, const char*>> ops = {{BinaryOp::add, "add"},
                                                             {BinaryOp::sub, "sub"},
                                                             {BinaryOp::mul, "mul"},
                                                             {BinaryOp::div, "div"},
                                                             {BinaryOp::minimum, "minimum"},
                                                             {BinaryOp::maximum, "maximum"},
                                                             {BinaryOp::gt, "gt"},
                                                             {BinaryOp::ge, "ge"},
                                                             {BinaryOp::lt, "lt"},
                                                             {BinaryOp::le, "le"},
                                                             {BinaryOp::eq, "eq"}};
  for (const BroadcastCase& c : broadcast_cases()) {
    for (const auto& [op, name] : ops) {
      const bool compare = op >= BinaryOp::gt;
      const Pair a = c.a(gen, c.out, compare ? Values::integer : Values::normal);
      const Pair b = c.b(
          gen, c.out,
          compare ? Values::integer : (op == BinaryOp::div ? Values::positive : Values::normal));
      const BinaryParams p{op};
      expect_close(run_both(OpId::binary, {a, b}, {c.out}, &p), compare ? 0.0 : 1e-6,
                   std::string(name) + " " + c.name);
    }
  }
}

TEST(CpuKernels, WhereWithBroadcasting) {
  Generator gen(4);
  for (const BroadcastCase& c : broadcast_cases()) {
    for (int layout = 0; layout < 3; ++layout) {
      // cond: full mask, a broadcast mask (the layout of b), or a scalar mask.
      Pair cond = integers(c.out, gen, 0, 2);
      if (layout == 1) {
        cond = c.b(gen, c.out, Values::integer);
      } else if (layout == 2) {
        cond = broadcast(integers({}, gen, 0, 2), c.out);
      }
      const Pair a = c.a(gen, c.out, Values::normal), b = c.b(gen, c.out, Values::normal);
      expect_close(run_both(OpId::where, {cond, a, b}, {c.out}, nullptr), 0.0,
                   "where " + c.name + " cond layout " + std::to_string(layout));
    }
  }
}

// ---- reduce_sum --------------------------------------------------------------------------------

TEST(CpuKernels, ReduceSumOverAnyDims) {
  Generator gen(5);
  struct Case {
    Shape shape;
    std::vector<int> dims;
  };
  const std::vector<Case> cases = {
      {{7}, {0}},
      {{1}, {0}},
      {{}, {}},
      {{3, 5, 7}, {0, 1, 2}},
      {{3, 5, 7}, {2}},
      {{3, 5, 7}, {0}},
      {{3, 5, 7}, {1}},
      {{3, 5, 7}, {0, 2}},
      {{3, 5, 7}, {}},
      {{2, 3, 5, 7}, {0, 2, 3}},
      {{2, 3, 5, 7}, {1}},
      {{2, 3, 5, 7}, {0, 1}},
      {{2, 3, 5, 7}, {2, 3}},
      {{1, 3, 1, 5}, {0, 2}},
      {{4, 1, 6}, {1}},
      {{8, 16, 40, 50}, {0, 2, 3}},   // keep C, many channels
      {{2, 3, 200, 300}, {0, 2, 3}},  // keep C, few channels: partial sums
      {{1, 1, 300, 400}, {0, 1, 2, 3}},
      {{200000}, {0}},
      {{64, 3000}, {0}},   // leading dim: rows
      {{30000, 3}, {0}},   // leading dim, short rows: per-thread partial rows
      {{5, 100000}, {1}},  // last dim, few rows
      {{4000, 37}, {1}},   // last dim, many rows
      {{6, 7, 800, 3}, {1, 2}},
  };
  for (const Case& c : cases) {
    const Pair x = normal(c.shape, gen);
    Shape out;
    for (int d = 0; d < static_cast<int>(c.shape.size()); ++d) {
      if (std::find(c.dims.begin(), c.dims.end(), d) == c.dims.end()) out.push_back(c.shape[d]);
    }
    ReduceParams p;
    p.dims = c.dims;
    std::string dims;
    for (int d : c.dims) dims += std::to_string(d) + ",";
    expect_close(run_both(OpId::reduce_sum, {x}, {out}, &p), 1e-6,
                 "reduce_sum " + shape_text(c.shape) + " over {" + dims + "}");
  }
}

// ---- concat / pad ------------------------------------------------------------------------------

TEST(CpuKernels, ConcatAlongEachDim) {
  Generator gen(6);
  const Shape base = {2, 3, 4, 5};
  for (int dim = 0; dim < 4; ++dim) {
    std::vector<Pair> in;
    Shape out = base;
    out[dim] = 0;
    for (int64_t len : {1, 3, 0, 2}) {
      Shape s = base;
      s[dim] = len;
      in.push_back(normal(s, gen));
      out[dim] += len;
    }
    const ConcatParams p{dim};
    expect_close(run_both(OpId::concat, in, {out}, &p), 0.0, "concat dim " + std::to_string(dim));
  }
  const ConcatParams p{1};
  expect_close(run_both(OpId::concat, {normal({4, 32, 60, 70}, gen), normal({4, 16, 60, 70}, gen)},
                        {{4, 48, 60, 70}}, &p),
               0.0, "large concat");
}

TEST(CpuKernels, PadConstantAsymmetric) {
  Generator gen(7);
  struct Case {
    Shape shape;
    std::vector<int64_t> before, after;
  };
  const std::vector<Case> cases = {
      {{5}, {2}, {3}},
      {{2, 3, 4, 5}, {0, 1, 2, 3}, {1, 0, 3, 2}},
      {{1, 1, 1, 1}, {1, 1, 1, 1}, {1, 1, 1, 1}},
      {{2, 3, 4, 5}, {0, 0, 0, 0}, {0, 0, 0, 0}},
      {{3, 4}, {0, 0}, {0, 5}},
      {{4, 16, 90, 110}, {0, 0, 3, 1}, {0, 0, 2, 4}},
  };
  for (const Case& c : cases) {
    PadParams p;
    p.before = c.before;
    p.after = c.after;
    p.value = 0.5;
    Shape out = c.shape;
    for (size_t d = 0; d < out.size(); ++d) out[d] += c.before[d] + c.after[d];
    expect_close(run_both(OpId::pad, {normal(c.shape, gen)}, {out}, &p), 0.0,
                 "pad " + shape_text(c.shape));
  }
}

// ---- optimisers --------------------------------------------------------------------------------

TEST(CpuKernels, AdamUpdate) {
  Generator gen(11);
  struct Case {
    double wd;
    int64_t step;
  };
  for (const Case& c : std::vector<Case>{{0.0, 1}, {0.01, 1}, {0.0, 10}, {0.05, 1000}}) {
    for (int64_t n : {1, 17, 100003}) {
      AdamParams p;
      p.lr = 1e-3;
      p.weight_decay = c.wd;
      p.step = c.step;
      const Pair param = normal({n}, gen), grad = normal({n}, gen), m = normal({n}, gen, 0.1);
      const Pair v = uniform({n}, gen, 0.0, 0.5);
      // Compare param, m and v after the step (grad is compared too: it must not change).
      expect_close(run_both(OpId::adam_update, {param, grad, m, v}, {}, &p, true), 1e-5,
                   "adam wd " + std::to_string(c.wd) + " step " + std::to_string(c.step) + " n " +
                       std::to_string(n));
    }
  }
}

TEST(CpuKernels, SgdUpdate) {
  Generator gen(12);
  struct Case {
    double momentum, dampening, wd;
    bool nesterov, first;
  };
  const std::vector<Case> cases = {{0.0, 0.0, 0.0, false, true},   {0.0, 0.0, 0.01, false, false},
                                   {0.9, 0.0, 0.0, false, true},   {0.9, 0.0, 0.0, false, false},
                                   {0.9, 0.1, 0.01, false, false}, {0.9, 0.0, 0.01, true, false}};
  for (const Case& c : cases) {
    SgdParams p;
    p.lr = 0.05;
    p.momentum = c.momentum;
    p.dampening = c.dampening;
    p.weight_decay = c.wd;
    p.nesterov = c.nesterov;
    p.first_step = c.first;
    const int64_t n = 50001;
    const Pair param = normal({n}, gen), grad = normal({n}, gen);
    const Pair buf = c.momentum != 0.0 ? normal({n}, gen) : Pair{};
    expect_close(run_both(OpId::sgd_update, {param, grad, buf}, {}, &p, true), 1e-5,
                 "sgd momentum " + std::to_string(c.momentum) + (c.nesterov ? " nesterov" : "") +
                     (c.first ? " first" : ""));
  }
}

}  // namespace
}  // namespace cvd

namespace cvd::test {
namespace {

// Layer norm and softmax over the last dim, as the ViT uses them (rows of its width, many rows:
// the threaded path and the per-thread gamma / beta partial sums) and at the edges (one column,
// one row).
TEST(CpuKernels, LayerNormAndSoftmaxRows) {
  Generator gen(23);
  for (const Shape& s :
       {Shape{1, 1}, Shape{5, 1}, Shape{1, 9}, Shape{3, 7, 13}, Shape{2, 600, 384}}) {
    const Shape c{s.back()};
    int64_t rows = 1;
    for (size_t d = 0; d + 1 < s.size(); ++d) rows *= s[d];
    const std::string what = shape_text(s);
    const LayerNormParams p{1e-6};
    const Pair x = normal(s, gen, 3.0), gamma = uniform(c, gen, 0.5, 1.5), beta = normal(c, gen);
    const Results fwd = run_both(OpId::layer_norm, {x, gamma, beta}, {s, {rows}, {rows}}, &p);
    expect_close(fwd, 1e-5, "layer_norm " + what);
    const Results plain = run_both(OpId::layer_norm, {x, Pair{}, Pair{}}, {s, {rows}, {rows}}, &p);
    expect_close(plain, 1e-5, "layer_norm without affine " + what);
    const Pair mean = pair_of(fwd.ref.at(1), {rows}), invstd = pair_of(fwd.ref.at(2), {rows});
    expect_close(run_both(OpId::layer_norm_backward, {normal(s, gen), x, gamma, mean, invstd},
                          {s, c, c}, &p),
                 1e-4, "layer_norm backward " + what);
    const Pair logits = normal(s, gen, 5.0);
    const Results y = run_both(OpId::softmax, {logits}, {s}, nullptr);
    expect_close(y, 1e-5, "softmax " + what);
    expect_close(
        run_both(OpId::softmax_backward, {normal(s, gen), pair_of(y.ref.at(0), s)}, {s}, nullptr),
        1e-5, "softmax backward " + what);
  }
}

}  // namespace
}  // namespace cvd::test
