// Part of the cvd_test_support library: the kernel table's element-wise, reduction, layout,
// optimiser, row-normalisation and matmul cases (tests/kernel_case_table.h).
//
// Tolerances (max |fast - ref| <= tol * max |ref| over each output):
//   exact (0): copy, fill, concat, pad, where, comparisons;
//   1e-6: binary arithmetic, reduce_sum (double accumulation);
//   2e-6: unary, unary_backward (f32 transcendentals);
//   1e-5: adam, sgd, layer norm and softmax forward, matmul; 1e-4: layer norm backward (long row sums).
#include <algorithm>
#include <string>
#include <tuple>
#include <utility>

#include "engine/kernel_params.h"
#include "tests/kernel_case_table.h"

namespace cvd::test {
namespace {

using Calls = std::vector<KernelCall>;

Calls copy_calls() {
  Generator gen(1);
  const Pair big = normal({6, 40, 50}, gen);
  const std::vector<std::pair<std::string, Pair>> sources = {
      {"contiguous", normal({3, 5, 7}, gen)},
      {"large contiguous", normal({4, 64, 33, 41}, gen)},
      {"permuted nchw->nhwc", permuted({2, 3, 4, 5}, {0, 2, 3, 1}, gen)},
      {"permuted 4-d", permuted({3, 4, 5, 6}, {2, 0, 3, 1}, gen)},
      {"transposed large", permuted({300, 257}, {1, 0}, gen)},
      {"row broadcast", broadcast(normal({5}, gen), {4, 5})},
      {"column broadcast", broadcast(normal({4, 1}, gen), {4, 6})},
      {"broadcast to 3-d", broadcast(normal({5, 1}, gen), {4, 5, 7})},
      {"scalar broadcast", broadcast(normal({}, gen), {3, 4})},
      {"narrowed", view(big, {6, 20, 30}, {2000, 50, 1}, 5 * 50 + 7)},
      {"zero-dim", normal({}, gen)},
      {"one element", normal({1, 1, 1}, gen)},
  };
  Calls calls;
  for (const auto& [name, src] : sources) {
    for (DType dst : {DType::f32, DType::f64}) {
      KernelCall c{
          "copy " + name + " to " + dtype_name(dst), OpId::copy, {src}, {src.t64.shape()}, nullptr};
      c.out_dtype = dst;
      calls.push_back(c);
    }
  }
  return calls;
}

Calls fill_calls() {
  Calls calls;
  for (const Shape& s : std::vector<Shape>{{}, {1}, {7, 3}, {3, 50, 1000}})
    calls.push_back({"fill " + shape_text(s), OpId::fill, {}, {s}, params_of(FillParams{-2.75})});
  return calls;
}

struct UnaryCase {
  UnaryOp op;
  double a, b;
  bool positive;  // domain x > 0 (log, sqrt, pow, reciprocal)
  const char* name;
};

Calls unary_calls() {
  const UnaryCase cases[] = {
      {UnaryOp::relu, 0, 0, false, "relu"},
      // Bounds exact in f32: clip's backward reads the output (y strictly inside the bounds),
      // and both kernels get the same f32-rounded y, which an inexact bound (0.7) would put on
      // different sides of the f64 and f32 bound.
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
      {UnaryOp::softplus, 0, 0, false, "softplus"},
  };
  Generator gen(2);
  Calls calls;
  for (const UnaryCase& u : cases) {
    for (const Shape& s : std::vector<Shape>{{1}, {13}, {3, 7, 11}, {2, 16, 41, 47}}) {
      const std::string what = std::string(u.name) + " " + shape_text(s);
      const Pair x = u.positive ? uniform(s, gen, 0.1, 3.0) : normal(s, gen, 2.0);
      const auto p = params_of(UnaryParams{u.op, u.a, u.b});
      calls.push_back({what + " forward", OpId::unary, {x}, {s}, p, 2e-6});
      // y as the reference computes it (rounded to f32 for both), gy random.
      const Pair y = pair_of(reference_outputs(OpId::unary, {x}, {s}, p.get()).at(0), s);
      calls.push_back(
          {what + " backward", OpId::unary_backward, {normal(s, gen), x, y}, {s}, p, 2e-6});
    }
  }
  return calls;
}

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

Calls binary_calls() {
  const std::pair<BinaryOp, const char*> ops[] = {{BinaryOp::add, "add"},
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
  Generator gen(3);
  Calls calls;
  for (const BroadcastCase& c : broadcast_cases()) {
    for (const auto& [op, name] : ops) {
      const bool compare = op >= BinaryOp::gt;
      const Pair a = c.a(gen, c.out, compare ? Values::integer : Values::normal);
      const Pair b = c.b(
          gen, c.out,
          compare ? Values::integer : (op == BinaryOp::div ? Values::positive : Values::normal));
      calls.push_back({std::string(name) + " " + c.name,
                       OpId::binary,
                       {a, b},
                       {c.out},
                       params_of(BinaryParams{op}),
                       compare ? 0.0 : 1e-6});
    }
  }
  return calls;
}

Calls where_calls() {
  Generator gen(4);
  Calls calls;
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
      calls.push_back({"where " + c.name + " cond layout " + std::to_string(layout),
                       OpId::where,
                       {cond, a, b},
                       {c.out},
                       nullptr});
    }
  }
  return calls;
}

Calls reduce_sum_calls() {
  const std::pair<Shape, std::vector<int>> cases[] = {
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
      {{3, 4, 5, 6}, {1, 3}},
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
      {{3, 20000}, {1}},   // long rows: CUDA's two-pass (chunked) path
      {{2, 5, 3000}, {0, 2}},
      {{6, 7, 800, 3}, {1, 2}},
  };
  Generator gen(5);
  Calls calls;
  for (const auto& [shape, dims] : cases) {
    Shape out;
    for (int d = 0; d < static_cast<int>(shape.size()); ++d)
      if (std::find(dims.begin(), dims.end(), d) == dims.end()) out.push_back(shape[d]);
    std::string names;
    for (int d : dims) names += std::to_string(d) + ",";
    calls.push_back({"reduce_sum " + shape_text(shape) + " over {" + names + "}",
                     OpId::reduce_sum,
                     {normal(shape, gen)},
                     {out},
                     params_of(ReduceParams{dims}),
                     1e-6});
  }
  return calls;
}

Calls concat_calls() {
  Generator gen(6);
  Calls calls;
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
    calls.push_back({"concat dim " + std::to_string(dim),
                     OpId::concat,
                     in,
                     {out},
                     params_of(ConcatParams{dim})});
  }
  calls.push_back({"large concat",
                   OpId::concat,
                   {normal({4, 32, 60, 70}, gen), normal({4, 16, 60, 70}, gen)},
                   {{4, 48, 60, 70}},
                   params_of(ConcatParams{1})});
  return calls;
}

Calls pad_calls() {
  struct Case {
    Shape shape;
    std::vector<int64_t> before, after;
  };
  const Case cases[] = {
      {{5}, {2}, {3}},
      {{2, 3, 4, 5}, {0, 1, 2, 3}, {1, 0, 3, 2}},
      {{1, 1, 1, 1}, {1, 1, 1, 1}, {1, 1, 1, 1}},
      {{2, 3, 4, 5}, {0, 0, 0, 0}, {0, 0, 0, 0}},
      {{3, 4}, {0, 0}, {0, 5}},
      {{4, 16, 90, 110}, {0, 0, 3, 1}, {0, 0, 2, 4}},
  };
  Generator gen(7);
  Calls calls;
  for (const Case& c : cases) {
    PadParams p;
    p.before = c.before;
    p.after = c.after;
    p.value = 0.5;
    Shape out = c.shape;
    for (size_t d = 0; d < out.size(); ++d) out[d] += c.before[d] + c.after[d];
    calls.push_back(
        {"pad " + shape_text(c.shape), OpId::pad, {normal(c.shape, gen)}, {out}, params_of(p)});
  }
  return calls;
}

Calls adam_calls() {
  Generator gen(11);
  Calls calls;
  for (const auto& [wd, step] :
       std::vector<std::pair<double, int64_t>>{{0.0, 1}, {0.01, 1}, {0.0, 10}, {0.05, 1000}}) {
    for (const Shape& s : std::vector<Shape>{{1}, {17}, {5, 33}, {100003}}) {
      AdamParams p;
      p.lr = 1e-3;
      p.weight_decay = wd;
      p.step = step;
      // Compares param, m and v after the step (and grad, which must not change).
      KernelCall c{
          "adam wd " + std::to_string(wd) + " step " + std::to_string(step) + " " + shape_text(s),
          OpId::adam_update,
          {normal(s, gen), normal(s, gen), normal(s, gen, 0.1), uniform(s, gen, 0.0, 0.5)},
          {},
          params_of(p),
          1e-5};
      c.read_inputs = true;
      c.min_scale = 1;
      calls.push_back(c);
    }
  }
  return calls;
}

Calls sgd_calls() {
  struct Case {
    double momentum, dampening, wd;
    bool nesterov, first;
  };
  const Case cases[] = {{0.0, 0.0, 0.0, false, true},   {0.0, 0.0, 0.01, false, false},
                        {0.9, 0.0, 0.0, false, true},   {0.9, 0.0, 0.0, false, false},
                        {0.9, 0.1, 0.01, false, false}, {0.9, 0.0, 0.01, true, false},
                        {0.9, 0.0, 1e-3, true, true}};
  Generator gen(12);
  Calls calls;
  for (const Case& c : cases) {
    SgdParams p;
    p.lr = 0.05;
    p.momentum = c.momentum;
    p.dampening = c.dampening;
    p.weight_decay = c.wd;
    p.nesterov = c.nesterov;
    p.first_step = c.first;
    for (const Shape& s : std::vector<Shape>{{5, 33}, {50001}}) {
      const Pair buf = c.momentum != 0.0 ? normal(s, gen) : Pair{};
      KernelCall k{"sgd momentum " + std::to_string(c.momentum) + (c.nesterov ? " nesterov" : "") +
                       (c.first ? " first" : "") + " " + shape_text(s),
                   OpId::sgd_update,
                   {normal(s, gen), normal(s, gen), buf},
                   {},
                   params_of(p),
                   1e-5};
      k.read_inputs = true;
      k.min_scale = 1;
      calls.push_back(k);
    }
  }
  return calls;
}

// Layer norm over the last dim, as the ViT uses it (rows of its width, many rows: the threaded
// path and the per-thread gamma / beta partial sums) and at the edges (one column, one row);
// with and without the affine parameters.
Calls layer_norm_calls() {
  Generator gen(23);
  Calls calls;
  for (const Shape& s : {Shape{1, 1}, Shape{5, 1}, Shape{4, 1}, Shape{1, 9}, Shape{3, 7},
                         Shape{3, 7, 13}, Shape{2, 5, 384}, Shape{2, 600, 384}}) {
    const Shape c{s.back()};
    const Shape rows{shape_numel(s) / s.back()};
    const auto p = params_of(LayerNormParams{1e-6});
    for (bool affine : {true, false}) {
      const std::string what = shape_text(s) + (affine ? " affine" : "");
      const Pair x = normal(s, gen, 3.0);
      const Pair gamma = affine ? uniform(c, gen, 0.5, 1.5) : Pair{};
      const Pair beta = affine ? normal(c, gen) : Pair{};
      calls.push_back(
          {"layer_norm " + what, OpId::layer_norm, {x, gamma, beta}, {s, rows, rows}, p, 1e-5});
      const auto fwd =
          reference_outputs(OpId::layer_norm, {x, gamma, beta}, {s, rows, rows}, p.get());
      const Pair mean = pair_of(fwd.at(1), rows), invstd = pair_of(fwd.at(2), rows);
      calls.push_back(
          {"layer_norm backward " + what,
           OpId::layer_norm_backward,
           {normal(s, gen), x, gamma, mean, invstd},
           affine ? std::vector<Shape>{s, c, c} : std::vector<Shape>{s, kUndefined, kUndefined},
           p,
           1e-4});
    }
  }
  return calls;
}

Calls softmax_calls() {
  Generator gen(24);
  Calls calls;
  for (const Shape& s : {Shape{1, 1}, Shape{5, 1}, Shape{1, 9}, Shape{3, 7, 13}, Shape{2, 5, 384},
                         Shape{2, 600, 384}}) {
    const Pair logits = normal(s, gen, 5.0);
    calls.push_back({"softmax " + shape_text(s), OpId::softmax, {logits}, {s}, nullptr, 1e-5});
    const Pair y = pair_of(reference_outputs(OpId::softmax, {logits}, {s}, nullptr).at(0), s);
    calls.push_back({"softmax backward " + shape_text(s),
                     OpId::softmax_backward,
                     {normal(s, gen), y},
                     {s},
                     nullptr,
                     1e-5});
  }
  return calls;
}

// Batched matmul with either operand transposed, a batch of one broadcast over the other's, and
// odd sizes.
Calls matmul_calls() {
  Generator gen(25);
  Calls calls;
  for (bool ta : {false, true}) {
    for (bool tb : {false, true}) {
      for (const auto& [b, m, k, n, bb] :
           std::vector<std::tuple<int64_t, int64_t, int64_t, int64_t, int64_t>>{
               {3, 17, 33, 9, 1}, {2, 1, 5, 1, 2}, {1, 64, 128, 96, 1}}) {
        const Pair a = normal(ta ? Shape{b, k, m} : Shape{b, m, k}, gen);
        const Pair w = normal(tb ? Shape{bb, n, k} : Shape{bb, k, n}, gen);
        calls.push_back({"matmul " + shape_text(a.t64.shape()) + (ta ? "^T" : "") + " x " +
                             shape_text(w.t64.shape()) + (tb ? "^T" : ""),
                         OpId::matmul,
                         {a, w},
                         {{b, m, n}},
                         params_of(MatmulParams{ta, tb}),
                         1e-5});
      }
    }
  }
  return calls;
}

}  // namespace

std::vector<KernelCase> elementwise_kernel_cases() {
  return {{"copy", copy_calls},
          {"fill", fill_calls},
          {"unary", unary_calls},
          {"binary", binary_calls},
          {"where", where_calls},
          {"reduce_sum", reduce_sum_calls},
          {"concat", concat_calls},
          {"pad", pad_calls},
          {"adam_update", adam_calls},
          {"sgd_update", sgd_calls},
          {"layer_norm", layer_norm_calls},
          {"softmax", softmax_calls},
          {"matmul", matmul_calls}};
}

std::vector<KernelCase> all_kernel_cases() {
  std::vector<KernelCase> cases = elementwise_kernel_cases();
  for (KernelCase& c : spatial_kernel_cases()) cases.push_back(std::move(c));
  return cases;
}

}  // namespace cvd::test
