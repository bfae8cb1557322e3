// The CUDA kernel bodies (kernels/cuda/*_body.h) run on the CPU by an emulated launch (a loop over
// every thread index, kernels/cuda/launch_body.h), through the same op drivers the CUDA backend
// registers, and compared with the float64 reference kernels (kernel_registry().find(op, cpu,
// f64)) on random inputs, op by op and (EmulatedCudaOpTable, at the end) as a backend of the op
// table. Plain C++: runs in every build, with or without nvcc or a GPU. Only
// matmul (a cuBLAS call, no hand-written body) is not covered here; tests/test_cuda_ops.cpp runs
// it on a real device. Tolerances: max |emulated - ref| <= tol * max |ref| per output, tol stated
// per case (1e-5 for short sums, 1e-4 for long reductions in f32).
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "engine/backend_registry.h"
#include "kernels/cuda/conv_body.h"
#include "kernels/cuda/correlation_body.h"
#include "kernels/cuda/layout_body.h"
#include "kernels/cuda/norm_pool_body.h"
#include "kernels/cuda/pointwise_body.h"
#include "kernels/cuda/resample_body.h"
#include "kernels/cuda/rows_body.h"
#include "tests/cpu_kernel_comparison.h"
#include "tests/op_case_run.h"

namespace cvd::test {
namespace {

using cuda::EmulatedLaunch;
using Driver = void (*)(const KernelArgs&);

const Shape kUndefined{-1};  // marks an output that is not requested

// Runs `driver` (an emulated CUDA op) on the f32 halves and the reference kernel of `op` on the
// f64 halves; returns both sets of outputs (and of inputs when read_inputs: in-place ops).
Results run_emulated(Driver driver, OpId op, const std::vector<Pair>& in,
                     const std::vector<Shape>& out_shapes, const void* params,
                     bool read_inputs = false, DType out_dtype = DType::f32) {
  const KernelInfo* ref = kernel_registry().find(op, DeviceType::cpu, DType::f64);
  EXPECT_TRUE(ref != nullptr) << op_name(op);
  if (!ref) return {};
  KernelArgs a32, a64;
  a32.params = a64.params = params;
  for (const Pair& p : in) {
    a32.in.push_back(p.t32);
    a64.in.push_back(p.t64);
  }
  for (const Shape& s : out_shapes) {
    const bool used = s != kUndefined;
    a32.out.push_back(used ? nan_filled(s, out_dtype) : Tensor());
    a64.out.push_back(used ? nan_filled(s, DType::f64) : Tensor());
  }
  driver(a32);
  ref->fn(a64);
  Results r;
  for (size_t i = 0; i < out_shapes.size(); ++i) {
    if (!a32.out[i].defined()) continue;
    r.fast.push_back(values_of(a32.out[i]));
    r.ref.push_back(values_of(a64.out[i]));
  }
  if (read_inputs) {
    for (size_t i = 0; i < in.size(); ++i) {
      if (!in[i].t64.defined()) continue;
      r.fast.push_back(values_of(a32.in[i]));
      r.ref.push_back(values_of(a64.in[i]));
    }
  }
  return r;
}

// ---- element-wise
// --------------------------------------------------------------------------------

TEST(CudaEmulated, CopyStridedAndConverting) {
  Generator gen(1);
  const Pair src = permuted({3, 4, 5, 6}, {2, 0, 3, 1}, gen);
  expect_close(
      run_emulated(cuda::copy_op<EmulatedLaunch>, OpId::copy, {src}, {{3, 4, 5, 6}}, nullptr), 0.0,
      "copy permuted f32");
  expect_close(run_emulated(cuda::copy_op<EmulatedLaunch>, OpId::copy, {src}, {{3, 4, 5, 6}},
                            nullptr, false, DType::f64),
               0.0, "copy permuted f32 -> f64");
  const Pair bcast = broadcast(normal({5, 1}, gen), {4, 5, 7});
  expect_close(
      run_emulated(cuda::copy_op<EmulatedLaunch>, OpId::copy, {bcast}, {{4, 5, 7}}, nullptr), 0.0,
      "copy broadcast view");
}

TEST(CudaEmulated, Fill) {
  const FillParams p{-2.5};
  expect_close(run_emulated(cuda::fill_op<EmulatedLaunch>, OpId::fill, {}, {{3, 17}}, &p), 0.0,
               "fill");
}

TEST(CudaEmulated, UnaryForwardAndBackward) {
  struct Case {
    UnaryOp op;
    double a, b;
    bool positive;
  };
  const Case cases[] = {{UnaryOp::relu, 0, 0, false},
                        {UnaryOp::clip, 0, 6, false},
                        {UnaryOp::leaky_relu, 0.1, 0, false},
                        {UnaryOp::sigmoid, 0, 0, false},
                        {UnaryOp::tanh, 0, 0, false},
                        {UnaryOp::exp, 0, 0, false},
                        {UnaryOp::log, 0, 0, true},
                        {UnaryOp::abs, 0, 0, false},
                        {UnaryOp::sqrt, 0, 0, true},
                        {UnaryOp::neg, 0, 0, false},
                        {UnaryOp::reciprocal, 0, 0, true},
                        {UnaryOp::pow_scalar, 1.7, 0, true},
                        {UnaryOp::mul_scalar, -3.5, 0, false},
                        {UnaryOp::add_scalar, 0.25, 0, false}};
  Generator gen(2);
  const Shape s{2, 3, 11, 13};
  for (const Case& c : cases) {
    const std::string what = "unary " + std::to_string(static_cast<int>(c.op));
    const Pair x = c.positive ? uniform(s, gen, 0.1, 3.0) : normal(s, gen, 2.0);
    const UnaryParams p{c.op, c.a, c.b};
    const Results fwd = run_emulated(cuda::unary_op<EmulatedLaunch>, OpId::unary, {x}, {s}, &p);
    expect_close(fwd, 2e-6, what + " forward");
    const Pair y = pair_of(fwd.ref.at(0), s);
    expect_close(run_emulated(cuda::unary_backward_op<EmulatedLaunch>, OpId::unary_backward,
                              {normal(s, gen), x, y}, {s}, &p),
                 2e-6, what + " backward");
  }
}

TEST(CudaEmulated, BinaryAndWhereWithBroadcasting) {
  Generator gen(3);
  const Shape out{2, 3, 7, 9};
  const Pair a = normal(out, gen);
  const Pair b = broadcast(uniform({1, 3, 1, 9}, gen, 0.5, 2.0), out);
  for (int op = 0; op <= static_cast<int>(BinaryOp::eq); ++op) {
    const BinaryParams p{static_cast<BinaryOp>(op)};
    expect_close(run_emulated(cuda::binary_op<EmulatedLaunch>, OpId::binary, {a, b}, {out}, &p),
                 1e-6, "binary " + std::to_string(op));
  }
  const Pair eq_a = integers(out, gen, -2, 3);
  const Pair eq_b = broadcast(integers({7, 1}, gen, -2, 3), out);
  const BinaryParams eq{BinaryOp::eq};
  expect_close(
      run_emulated(cuda::binary_op<EmulatedLaunch>, OpId::binary, {eq_a, eq_b}, {out}, &eq), 0.0,
      "binary eq on integers");
  const Pair cond = broadcast(integers({1, 1, 7, 1}, gen, 0, 2), out);
  const Pair transposed = permuted(out, {0, 1, 3, 2}, gen);
  expect_close(run_emulated(cuda::where_op<EmulatedLaunch>, OpId::where, {cond, transposed, b},
                            {out}, nullptr),
               0.0, "where");
}

TEST(CudaEmulated, AdamAndSgdUpdates) {
  Generator gen(4);
  const Shape s{5, 33};
  AdamParams ap;
  ap.lr = 1e-2, ap.weight_decay = 0.01, ap.step = 3;
  expect_close(
      run_emulated(cuda::adam_update_op<EmulatedLaunch>, OpId::adam_update,
                   {normal(s, gen), normal(s, gen), normal(s, gen, 0.1), uniform(s, gen, 0.0, 0.1)},
                   {}, &ap, true),
      1e-5, "adam");
  for (bool nesterov : {false, true}) {
    for (bool first : {false, true}) {
      SgdParams sp;
      sp.lr = 0.1, sp.momentum = 0.9, sp.dampening = nesterov ? 0.0 : 0.1;
      sp.weight_decay = 1e-3, sp.nesterov = nesterov, sp.first_step = first;
      expect_close(run_emulated(cuda::sgd_update_op<EmulatedLaunch>, OpId::sgd_update,
                                {normal(s, gen), normal(s, gen), normal(s, gen)}, {}, &sp, true),
                   1e-5, "sgd");
    }
  }
}

// ---- layout -------------------------------------------------------------------------------------

TEST(CudaEmulated, ReduceSumConcatPad) {
  Generator gen(5);
  const Shape s{3, 4, 5, 6};
  for (const std::vector<int>& dims :
       std::vector<std::vector<int>>{{}, {0}, {1}, {3}, {0, 2}, {1, 3}, {0, 2, 3}, {0, 1, 2, 3}}) {
    Shape out;
    for (int d = 0; d < 4; ++d)
      if (std::find(dims.begin(), dims.end(), d) == dims.end()) out.push_back(s[d]);
    const ReduceParams p{dims};
    expect_close(run_emulated(cuda::reduce_sum_op<EmulatedLaunch>, OpId::reduce_sum,
                              {normal(s, gen)}, {out}, &p),
                 1e-6, "reduce_sum over " + std::to_string(dims.size()) + " dims");
  }
  // Long reductions take the two-pass (chunked) path.
  for (const auto& [shape, dims] : std::vector<std::pair<Shape, std::vector<int>>>{
           {{3, 20000}, {1}}, {{2, 5, 3000}, {0, 2}}, {{40000}, {0}}}) {
    Shape out;
    for (int d = 0; d < static_cast<int>(shape.size()); ++d)
      if (std::find(dims.begin(), dims.end(), d) == dims.end()) out.push_back(shape[d]);
    const ReduceParams p{dims};
    expect_close(run_emulated(cuda::reduce_sum_op<EmulatedLaunch>, OpId::reduce_sum,
                              {normal(shape, gen)}, {out}, &p),
                 1e-6, "long reduce_sum " + shape_text(shape));
  }
  for (int dim = 0; dim < 3; ++dim) {
    Shape a{2, 3, 4}, b{2, 3, 4}, out{2, 3, 4};
    b[dim] = 5;
    out[dim] = 2 * a[dim] + 5;
    const ConcatParams p{dim};
    expect_close(run_emulated(cuda::concat_op<EmulatedLaunch>, OpId::concat,
                              {normal(a, gen), normal(b, gen), normal(a, gen)}, {out}, &p),
                 0.0, "concat dim " + std::to_string(dim));
  }
  PadParams pp;
  pp.before = {0, 1, 2, 0};
  pp.after = {1, 0, 3, 2};
  pp.value = -1.5;
  expect_close(run_emulated(cuda::pad_op<EmulatedLaunch>, OpId::pad, {normal({2, 3, 4, 5}, gen)},
                            {{3, 4, 9, 7}}, &pp),
               0.0, "pad");
}

// ---- resampling ---------------------------------------------------------------------------------

TEST(CudaEmulated, BicubicResizeForwardAndBackward) {
  Generator gen(16);
  struct Case {
    Shape in, out;
    UpsampleParams p;
  };
  const std::vector<Case> cases = {
      {{2, 3, 5, 7}, {2, 3, 9, 11}, {false}},
      {{1, 2, 9, 8}, {1, 2, 4, 3}, {false}},
      {{1, 2, 5, 4}, {1, 2, 8, 7}, {true}},
      {{1, 4, 5, 5}, {1, 4, 7, 4}, {false, 7.1 / 5, 4.1 / 5}},  // DINOv2's scale factors
      {{1, 1, 1, 1}, {1, 1, 3, 2}, {false}}};
  for (const Case& c : cases) {
    const std::string what = shape_text(c.in) + " -> " + shape_text(c.out);
    expect_close(run_emulated(cuda::upsample_bicubic2d_op<EmulatedLaunch>, OpId::upsample_bicubic2d,
                              {normal(c.in, gen)}, {c.out}, &c.p),
                 1e-5, "bicubic " + what);
    expect_close(
        run_emulated(cuda::upsample_bicubic2d_backward_op<EmulatedLaunch>,
                     OpId::upsample_bicubic2d_backward, {normal(c.out, gen)}, {c.in}, &c.p),
        1e-5, "bicubic backward " + what);
  }
}

// ---- row normalisations -------------------------------------------------------------------------

TEST(CudaEmulated, LayerNormAndSoftmaxForwardAndBackward) {
  Generator gen(17);
  for (const Shape& s : {Shape{3, 7}, Shape{2, 5, 384}, Shape{4, 1}}) {
    const Shape c{s.back()}, rows{s.size() == 3 ? s[0] * s[1] : s[0]};
    for (bool affine : {true, false}) {
      const std::string what = shape_text(s) + (affine ? " affine" : "");
      const LayerNormParams p{1e-6};
      const Pair x = normal(s, gen, 2.0);
      const Pair gamma = affine ? uniform(c, gen, 0.5, 1.5) : Pair{};
      const Pair beta = affine ? normal(c, gen) : Pair{};
      const Results fwd = run_emulated(cuda::layer_norm_op<EmulatedLaunch>, OpId::layer_norm,
                                       {x, gamma, beta}, {s, rows, rows}, &p);
      expect_close(fwd, 1e-5, "layer_norm " + what);
      const Pair mean = pair_of(fwd.ref.at(1), rows), invstd = pair_of(fwd.ref.at(2), rows);
      const std::vector<Shape> outs =
          affine ? std::vector<Shape>{s, c, c} : std::vector<Shape>{s, kUndefined, kUndefined};
      expect_close(
          run_emulated(cuda::layer_norm_backward_op<EmulatedLaunch>, OpId::layer_norm_backward,
                       {normal(s, gen), x, gamma, mean, invstd}, outs, &p),
          1e-4, "layer_norm backward " + what);
    }
    const Pair logits = normal(s, gen, 4.0);
    const Results y =
        run_emulated(cuda::softmax_op<EmulatedLaunch>, OpId::softmax, {logits}, {s}, nullptr);
    expect_close(y, 1e-5, "softmax " + shape_text(s));
    expect_close(run_emulated(cuda::softmax_backward_op<EmulatedLaunch>, OpId::softmax_backward,
                              {normal(s, gen), pair_of(y.ref.at(0), s)}, {s}, nullptr),
                 1e-5, "softmax backward " + shape_text(s));
  }
}

TEST(CudaEmulated, BilinearAndNearestResizeForwardAndBackward) {
  Generator gen(6);
  const std::vector<std::pair<Shape, Shape>> sizes = {
      {{2, 3, 5, 7}, {2, 3, 10, 14}}, {{1, 2, 9, 8}, {1, 2, 4, 3}},  {{1, 1, 4, 6}, {1, 1, 7, 13}},
      {{1, 2, 1, 5}, {1, 2, 3, 1}},   {{1, 1, 2, 2}, {1, 1, 82, 5}}, {{1, 1, 6, 6}, {1, 1, 6, 6}}};
  for (const auto& [in, out] : sizes) {
    const std::string what = shape_text(in) + " -> " + shape_text(out);
    for (bool ac : {false, true}) {
      const UpsampleParams p{ac};
      expect_close(run_emulated(cuda::upsample_bilinear2d_op<EmulatedLaunch>,
                                OpId::upsample_bilinear2d, {normal(in, gen)}, {out}, &p),
                   1e-5, "bilinear " + what);
      expect_close(run_emulated(cuda::upsample_bilinear2d_backward_op<EmulatedLaunch>,
                                OpId::upsample_bilinear2d_backward, {normal(out, gen)}, {in}, &p),
                   1e-5, "bilinear backward " + what);
    }
    expect_close(run_emulated(cuda::upsample_nearest2d_op<EmulatedLaunch>, OpId::upsample_nearest2d,
                              {normal(in, gen)}, {out}, nullptr),
                 0.0, "nearest " + what);
    expect_close(run_emulated(cuda::upsample_nearest2d_backward_op<EmulatedLaunch>,
                              OpId::upsample_nearest2d_backward, {normal(out, gen)}, {in}, nullptr),
                 1e-6, "nearest backward " + what);
  }
}

TEST(CudaEmulated, GridSampleForwardAndBackward) {
  Generator gen(7);
  const Shape x{2, 3, 6, 7}, grid{2, 5, 4, 2}, y{2, 3, 5, 4};
  for (GridPadding pad : {GridPadding::zeros, GridPadding::border}) {
    for (bool ac : {false, true}) {
      const GridSampleParams p{pad, ac};
      const std::string what = std::string(pad == GridPadding::zeros ? "zeros" : "border") +
                               (ac ? " align_corners" : "");
      const Pair xv = normal(x, gen), gv = uniform(grid, gen, -1.2, 1.2);
      expect_close(
          run_emulated(cuda::grid_sample_op<EmulatedLaunch>, OpId::grid_sample, {xv, gv}, {y}, &p),
          1e-5, "grid_sample " + what);
      expect_close(
          run_emulated(cuda::grid_sample_backward_op<EmulatedLaunch>, OpId::grid_sample_backward,
                       {normal(y, gen), xv, gv}, {x, grid}, &p),
          1e-5, "grid_sample backward " + what);
      expect_close(
          run_emulated(cuda::grid_sample_backward_op<EmulatedLaunch>, OpId::grid_sample_backward,
                       {normal(y, gen), xv, gv}, {kUndefined, grid}, &p),
          1e-5, "grid_sample backward, grid only " + what);
    }
  }
}

// ---- normalisation and pooling ------------------------------------------------------------------

TEST(CudaEmulated, BatchNormTrainAndEval) {
  Generator gen(8);
  const Shape c{4};
  // The second shape has 2 * 3 * 40 * 50 = 12000 elements per channel: several chunks.
  for (const Shape& s : {Shape{3, 4, 5, 6}, Shape{2, 4, 3, 40, 50}})
    for (bool training : {true, false}) {
      for (bool affine : {true, false}) {
        BatchNormParams p;
        p.training = training;
        const std::string what =
            std::string(training ? "train" : "eval") + (affine ? " affine" : "");
        const Pair x = normal(s, gen, 2.0);
        const Pair gamma = affine ? uniform(c, gen, 0.5, 1.5) : Pair{};
        const Pair beta = affine ? normal(c, gen) : Pair{};
        const Results fwd = run_emulated(
            cuda::batch_norm_op<EmulatedLaunch>, OpId::batch_norm,
            {x, gamma, beta, normal(c, gen), uniform(c, gen, 0.5, 2.0)}, {s, c, c}, &p, true);
        expect_close(fwd, 1e-5, "batch_norm " + what);
        const Pair mean = pair_of(fwd.ref.at(1), c), invstd = pair_of(fwd.ref.at(2), c);
        const std::vector<Shape> outs =
            affine ? std::vector<Shape>{s, c, c} : std::vector<Shape>{s, kUndefined, kUndefined};
        expect_close(
            run_emulated(cuda::batch_norm_backward_op<EmulatedLaunch>, OpId::batch_norm_backward,
                         {normal(s, gen), x, gamma, mean, invstd}, outs, &p),
            1e-5, "batch_norm backward " + what);
      }
    }
}

int64_t pool_out(int64_t in, int k, int s, int pb, int pa, bool ceil_mode) {
  const int64_t span = in + pb + pa - k;
  int64_t o = (ceil_mode ? (span + s - 1) / s : span / s) + 1;
  if (ceil_mode && (o - 1) * s >= in + pb) --o;  // PyTorch: last window starts inside
  return o;
}

TEST(CudaEmulated, MaxAndAvgPoolForwardAndBackward) {
  Generator gen(9);
  struct Case {
    Pool2dParams p;
    Shape x;
  };
  std::vector<Case> cases;
  Pool2dParams p;
  cases.push_back({p, {2, 3, 8, 9}});
  p.kernel_h = 3, p.kernel_w = 3, p.stride_h = 2, p.stride_w = 2, p.pad_top = 1, p.pad_left = 1;
  p.pad_bottom = 1, p.pad_right = 1;
  cases.push_back({p, {1, 2, 9, 10}});
  p.ceil_mode = true;
  p.count_include_pad = false;
  cases.push_back({p, {1, 2, 10, 7}});
  p.kernel_h = 2, p.kernel_w = 3, p.stride_h = 1, p.stride_w = 2, p.pad_top = 0, p.pad_left = 1;
  p.pad_bottom = 0, p.pad_right = 1, p.ceil_mode = false, p.count_include_pad = true;
  cases.push_back({p, {2, 1, 6, 7}});
  for (const Case& c : cases) {
    const Pool2dParams& q = c.p;
    const Shape y{c.x[0], c.x[1],
                  pool_out(c.x[2], q.kernel_h, q.stride_h, q.pad_top, q.pad_bottom, q.ceil_mode),
                  pool_out(c.x[3], q.kernel_w, q.stride_w, q.pad_left, q.pad_right, q.ceil_mode)};
    const std::string what = shape_text(c.x) + " -> " + shape_text(y);
    const Pair x = normal(c.x, gen);
    expect_close(run_emulated(cuda::max_pool2d_op<EmulatedLaunch>, OpId::max_pool2d, {x}, {y}, &q),
                 0.0, "max_pool " + what);
    expect_close(run_emulated(cuda::max_pool2d_backward_op<EmulatedLaunch>,
                              OpId::max_pool2d_backward, {normal(y, gen), x}, {c.x}, &q),
                 1e-6, "max_pool backward " + what);
    expect_close(run_emulated(cuda::avg_pool2d_op<EmulatedLaunch>, OpId::avg_pool2d, {x}, {y}, &q),
                 1e-6, "avg_pool " + what);
    expect_close(run_emulated(cuda::avg_pool2d_backward_op<EmulatedLaunch>,
                              OpId::avg_pool2d_backward, {normal(y, gen)}, {c.x}, &q),
                 1e-6, "avg_pool backward " + what);
  }
}

// ---- convolutions -------------------------------------------------------------------------------

TEST(CudaEmulated, Conv2dForwardAndBackward) {
  Generator gen(10);
  Conv2dParams p;
  p.stride_h = 2, p.stride_w = 1, p.pad_top = 1, p.pad_bottom = 2, p.pad_left = 0;
  p.pad_right = 1, p.dilation_h = 1, p.dilation_w = 2, p.groups = 2;
  const Shape x{2, 4, 9, 8}, w{6, 2, 3, 3};
  const int64_t oh = (9 + 1 + 2 - 1 * (3 - 1) - 1) / 2 + 1, ow = (8 + 0 + 1 - 2 * (3 - 1) - 1) + 1;
  const Shape y{2, 6, oh, ow};
  const Pair xv = normal(x, gen), wv = normal(w, gen), gy = normal(y, gen);
  expect_close(run_emulated(cuda::conv2d_op<EmulatedLaunch>, OpId::conv2d,
                            {xv, wv, normal({6}, gen)}, {y}, &p),
               1e-5, "conv2d");
  expect_close(
      run_emulated(cuda::conv2d_op<EmulatedLaunch>, OpId::conv2d, {xv, wv, Pair{}}, {y}, &p), 1e-5,
      "conv2d without bias");
  expect_close(run_emulated(cuda::conv2d_backward_data_op<EmulatedLaunch>,
                            OpId::conv2d_backward_data, {gy, wv}, {x}, &p),
               1e-5, "conv2d backward data");
  expect_close(run_emulated(cuda::conv2d_backward_weight_op<EmulatedLaunch>,
                            OpId::conv2d_backward_weight, {gy, xv}, {w, {6}}, &p),
               1e-5, "conv2d backward weight");
}

TEST(CudaEmulated, Conv2dWeightGradientInChunks) {
  // N * OH = 140 output rows of OW = 90: the weight gradient is summed in 4 chunks of 45 rows.
  Generator gen(13);
  Conv2dParams p;
  p.pad_top = p.pad_bottom = p.pad_left = p.pad_right = 1;
  const Shape x{2, 3, 70, 90}, w{4, 3, 3, 3}, y{2, 4, 70, 90};
  expect_close(
      run_emulated(cuda::conv2d_backward_weight_op<EmulatedLaunch>, OpId::conv2d_backward_weight,
                   {normal(y, gen), normal(x, gen)}, {w, {4}}, &p),
      1e-5, "conv2d backward weight, chunked");
}

TEST(CudaEmulated, ConvTranspose2dForwardAndBackward) {
  Generator gen(11);
  ConvTranspose2dParams p;
  p.stride_h = 2, p.stride_w = 3, p.pad_top = 1, p.pad_bottom = 0, p.pad_left = 1;
  p.pad_right = 2, p.output_padding_h = 1, p.output_padding_w = 0, p.dilation_h = 2;
  p.dilation_w = 1, p.groups = 2;
  const Shape x{2, 4, 5, 4}, w{4, 3, 3, 2};
  const int64_t oh = (5 - 1) * 2 - 1 - 0 + 2 * (3 - 1) + 1 + 1;
  const int64_t ow = (4 - 1) * 3 - 1 - 2 + 1 * (2 - 1) + 0 + 1;
  const Shape y{2, 6, oh, ow};
  const Pair xv = normal(x, gen), wv = normal(w, gen), gy = normal(y, gen);
  expect_close(run_emulated(cuda::conv_transpose2d_op<EmulatedLaunch>, OpId::conv_transpose2d,
                            {xv, wv, normal({6}, gen)}, {y}, &p),
               1e-5, "conv_transpose2d");
  expect_close(run_emulated(cuda::conv_transpose2d_backward_data_op<EmulatedLaunch>,
                            OpId::conv_transpose2d_backward_data, {gy, wv}, {x}, &p),
               1e-5, "conv_transpose2d backward data");
  expect_close(run_emulated(cuda::conv_transpose2d_backward_weight_op<EmulatedLaunch>,
                            OpId::conv_transpose2d_backward_weight, {gy, xv}, {w, {6}}, &p),
               1e-5, "conv_transpose2d backward weight");
}

// ---- correlation / channel norm ----------------------------------------------------------------

TEST(CudaEmulated, CorrelationAndChannelNorm) {
  Generator gen(12);
  struct Case {
    CorrelationParams p;
    Shape in;
  };
  const Case cases[] = {{{4, 1, 4, 1, 2}, {1, 3, 9, 10}}, {{2, 3, 2, 2, 1}, {2, 2, 11, 9}}};
  for (const Case& c : cases) {
    const Shape y{c.in[0], int64_t{c.p.displacement_size()} * c.p.displacement_size(),
                  c.p.out_size(c.in[2]), c.p.out_size(c.in[3])};
    const std::string what = "correlation k" + std::to_string(c.p.kernel_size);
    const Pair a = normal(c.in, gen), b = normal(c.in, gen);
    expect_close(
        run_emulated(cuda::correlation_op<EmulatedLaunch>, OpId::correlation, {a, b}, {y}, &c.p),
        1e-5, what);
    expect_close(
        run_emulated(cuda::correlation_backward_op<EmulatedLaunch>, OpId::correlation_backward,
                     {normal(y, gen), a, b}, {c.in, c.in}, &c.p),
        1e-5, what + " backward");
  }
  const Shape x{2, 5, 4, 3}, y{2, 1, 4, 3};
  const Pair xv = normal(x, gen);
  const Results fwd =
      run_emulated(cuda::channel_norm_op<EmulatedLaunch>, OpId::channel_norm, {xv}, {y}, nullptr);
  expect_close(fwd, 1e-6, "channel_norm");
  expect_close(
      run_emulated(cuda::channel_norm_backward_op<EmulatedLaunch>, OpId::channel_norm_backward,
                   {normal(y, gen), xv, pair_of(fwd.ref[0], y)}, {x}, nullptr),
      1e-6, "channel_norm backward");
}

// ---- the op table on the emulated bodies -------------------------------------------------------
// Every case of the op table (tests/op_case_table.cpp), forward and autograd backward, with the
// CPU's f32 kernels replaced by the CUDA drivers under the emulated launch (a backend registered
// in this process only; matmul, a cuBLAS call with no body, stays the CPU's), against the float64
// reference: the same comparison (tests/op_case_run.h) the CPU and the real device run.

#define CVD_EMULATED(registry, op, driver)                                       \
  (registry).add(                                                                \
      ::cvd::OpId::op, ::cvd::DeviceType::cpu, ::cvd::DType::f32,                \
      [](const ::cvd::KernelArgs& a) { cuda::driver<cuda::EmulatedLaunch>(a); }, \
      "cuda (emulated)")

void register_emulated_cuda_kernels(KernelRegistry& r) {
  CVD_EMULATED(r, conv2d, conv2d_op);
  CVD_EMULATED(r, conv2d_backward_data, conv2d_backward_data_op);
  CVD_EMULATED(r, conv2d_backward_weight, conv2d_backward_weight_op);
  CVD_EMULATED(r, conv_transpose2d, conv_transpose2d_op);
  CVD_EMULATED(r, conv_transpose2d_backward_data, conv_transpose2d_backward_data_op);
  CVD_EMULATED(r, conv_transpose2d_backward_weight, conv_transpose2d_backward_weight_op);
  CVD_EMULATED(r, correlation, correlation_op);
  CVD_EMULATED(r, correlation_backward, correlation_backward_op);
  CVD_EMULATED(r, channel_norm, channel_norm_op);
  CVD_EMULATED(r, channel_norm_backward, channel_norm_backward_op);
  CVD_EMULATED(r, reduce_sum, reduce_sum_op);
  CVD_EMULATED(r, concat, concat_op);
  CVD_EMULATED(r, pad, pad_op);
  CVD_EMULATED(r, batch_norm, batch_norm_op);
  CVD_EMULATED(r, batch_norm_backward, batch_norm_backward_op);
  CVD_EMULATED(r, max_pool2d, max_pool2d_op);
  CVD_EMULATED(r, max_pool2d_backward, max_pool2d_backward_op);
  CVD_EMULATED(r, avg_pool2d, avg_pool2d_op);
  CVD_EMULATED(r, avg_pool2d_backward, avg_pool2d_backward_op);
  CVD_EMULATED(r, copy, copy_op);
  CVD_EMULATED(r, fill, fill_op);
  CVD_EMULATED(r, unary, unary_op);
  CVD_EMULATED(r, unary_backward, unary_backward_op);
  CVD_EMULATED(r, binary, binary_op);
  CVD_EMULATED(r, where, where_op);
  CVD_EMULATED(r, adam_update, adam_update_op);
  CVD_EMULATED(r, sgd_update, sgd_update_op);
  CVD_EMULATED(r, upsample_bilinear2d, upsample_bilinear2d_op);
  CVD_EMULATED(r, upsample_bilinear2d_backward, upsample_bilinear2d_backward_op);
  CVD_EMULATED(r, upsample_nearest2d, upsample_nearest2d_op);
  CVD_EMULATED(r, upsample_nearest2d_backward, upsample_nearest2d_backward_op);
  CVD_EMULATED(r, upsample_bicubic2d, upsample_bicubic2d_op);
  CVD_EMULATED(r, upsample_bicubic2d_backward, upsample_bicubic2d_backward_op);
  CVD_EMULATED(r, grid_sample, grid_sample_op);
  CVD_EMULATED(r, grid_sample_backward, grid_sample_backward_op);
  CVD_EMULATED(r, layer_norm, layer_norm_op);
  CVD_EMULATED(r, layer_norm_backward, layer_norm_backward_op);
  CVD_EMULATED(r, softmax, softmax_op);
  CVD_EMULATED(r, softmax_backward, softmax_backward_op);
}

#undef CVD_EMULATED

// Registers the emulated bodies over the CPU's f32 kernels (once per process).
void use_emulated_cuda_kernels() {
  static const bool done = [] {
    BackendHooks b;
    b.name = "cuda-emulated-test";
    b.description = "CUDA kernel bodies, emulated launch on the CPU (tests only)";
    b.register_kernels = &register_emulated_cuda_kernels;
    register_backend(b);
    return true;
  }();
  (void)done;
}

class EmulatedCudaOpTable : public ::testing::TestWithParam<OpCase> {};

TEST_P(EmulatedCudaOpTable, F32VsReference) {
  use_emulated_cuda_kernels();
  ASSERT_STREQ(kernel_registry().find(OpId::binary, DeviceType::cpu, DType::f32)->impl,
               "cuda (emulated)");
  EXPECT_EQ(compare_with_reference(GetParam(), DeviceId::cpu(), 99), "");
}

TEST_P(EmulatedCudaOpTable, F32StridedInputsVsReference) {
  use_emulated_cuda_kernels();
  CompareOptions o;
  o.strided_inputs = true;
  EXPECT_EQ(compare_with_reference(GetParam(), DeviceId::cpu(), 99, o), "");
}

INSTANTIATE_TEST_SUITE_P(Ops, EmulatedCudaOpTable, ::testing::ValuesIn(all_op_cases()),
                         [](const ::testing::TestParamInfo<OpCase>& i) { return i.param.name; });

}  // namespace
}  // namespace cvd::test
