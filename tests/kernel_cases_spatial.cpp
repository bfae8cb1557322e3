// Part of the cvd_test_support library: the kernel table's resampling, normalisation, pooling,
// convolution and correlation cases (tests/kernel_case_table.h).
//
// Tolerances (max |fast - ref| <= tol * max |ref| over each output):
//   exact (0): nearest resize forward, max pooling forward;
//   1e-6: nearest backward, pooling backward, average pooling, channel norm;
//   1e-5: bilinear resize, grid_sample (x and grid gradients), batch norm, convolutions,
//         correlation;
//   3e-5: bicubic resize (the CUDA body computes its source coordinates and cubic weights in f32,
//         as PyTorch's CUDA kernel does; on a 2.6x downscale their rounding reaches 1.1e-5).
#include <cmath>
#include <optional>
#include <string>
#include <utility>

#include "engine/kernel_params.h"
#include "tests/kernel_case_table.h"

namespace cvd::test {
namespace {

using Calls = std::vector<KernelCall>;

// ---- resize -------------------------------------------------------------------------------------

struct ResizeCase {
  Shape in;  // N, C, H, W
  int64_t oh, ow;
};

const std::vector<ResizeCase>& resize_cases() {
  static const std::vector<ResizeCase> cases = {
      {{2, 3, 1, 1}, 1, 1},       {{2, 3, 1, 1}, 5, 4},      {{2, 3, 5, 4}, 1, 1},
      {{2, 3, 4, 6}, 8, 12},      {{2, 3, 8, 12}, 4, 6},     {{1, 2, 7, 9}, 13, 23},
      {{1, 2, 13, 23}, 7, 9},     {{2, 1, 3, 5}, 10, 6},     {{1, 1, 6, 10}, 10, 6},
      {{1, 2, 1, 5}, 3, 1},       {{1, 1, 2, 2}, 82, 5},     {{1, 1, 6, 6}, 6, 6},
      {{2, 8, 48, 64}, 96, 128},  {{2, 8, 96, 128}, 37, 51}, {{1, 1, 64, 80}, 150, 170},
      {{1, 3, 150, 170}, 64, 80},
  };
  return cases;
}

std::string resize_text(const Shape& in, const Shape& out, const UpsampleParams& p) {
  return shape_text(in) + " -> " + shape_text(out) +
         (p.align_corners ? " align_corners" : " half-pixel");
}

// A resize op and its backward on every resize case, both alignments.
Calls resize_calls(const std::string& name, OpId forward, OpId backward, uint64_t seed,
                   double tol) {
  Generator gen(seed);
  Calls calls;
  for (const ResizeCase& c : resize_cases()) {
    const Shape out = {c.in[0], c.in[1], c.oh, c.ow};
    for (bool ac : {false, true}) {
      const UpsampleParams p{ac};
      const std::string what = resize_text(c.in, out, p);
      calls.push_back({name + " " + what, forward, {normal(c.in, gen)}, {out}, params_of(p), tol});
      calls.push_back(
          {name + " backward " + what, backward, {normal(out, gen)}, {c.in}, params_of(p), tol});
    }
  }
  return calls;
}

Calls bilinear_calls() {
  return resize_calls("bilinear", OpId::upsample_bilinear2d, OpId::upsample_bilinear2d_backward, 8,
                      1e-5);
}

Calls bicubic_calls() {
  Calls calls = resize_calls("bicubic", OpId::upsample_bicubic2d, OpId::upsample_bicubic2d_backward,
                             18, 3e-5);
  // DINOv2 / Depth Anything: a 37 x 37 position-embedding grid to 28 x 37 patches with the scale
  // factors (n + 0.1) / 37 given; and a small one.
  Generator gen(19);
  for (const auto& [in, out] : std::vector<std::pair<Shape, Shape>>{
           {{1, 16, 37, 37}, {1, 16, 28, 37}}, {{1, 4, 5, 5}, {1, 4, 7, 4}}}) {
    const UpsampleParams p{false, (static_cast<double>(out[2]) + 0.1) / static_cast<double>(in[2]),
                           (static_cast<double>(out[3]) + 0.1) / static_cast<double>(in[3])};
    const std::string what = shape_text(in) + " -> " + shape_text(out) + " with scale factors";
    calls.push_back({"bicubic " + what,
                     OpId::upsample_bicubic2d,
                     {normal(in, gen)},
                     {out},
                     params_of(p),
                     1e-5});
    calls.push_back({"bicubic backward " + what,
                     OpId::upsample_bicubic2d_backward,
                     {normal(out, gen)},
                     {in},
                     params_of(p),
                     1e-5});
  }
  return calls;
}

Calls nearest_calls() {
  Generator gen(9);
  Calls calls;
  for (const ResizeCase& c : resize_cases()) {
    const Shape out = {c.in[0], c.in[1], c.oh, c.ow};
    const std::string what = shape_text(c.in) + " -> " + shape_text(out);
    calls.push_back(
        {"nearest " + what, OpId::upsample_nearest2d, {normal(c.in, gen)}, {out}, nullptr, 0.0});
    calls.push_back({"nearest backward " + what,
                     OpId::upsample_nearest2d_backward,
                     {normal(out, gen)},
                     {c.in},
                     nullptr,
                     1e-6});
  }
  return calls;
}

// ---- grid_sample --------------------------------------------------------------------------------

// Grid values whose pixel coordinates stay >= 0.02 px away from integers (so f32 and f64 pick the
// same bilinear cell) and extend `margin` pixels beyond the image on each side.
Pair sample_grid(int64_t n, int64_t oh, int64_t ow, int64_t h, int64_t w, bool align_corners,
                 double margin, Generator& gen) {
  std::vector<double> v(static_cast<size_t>(n * oh * ow * 2));
  for (size_t i = 0; i < v.size(); ++i) {
    const int64_t size = i % 2 == 0 ? w : h;
    if (align_corners && size == 1) {  // every coordinate maps to pixel 0
      v[i] = 2.0 * gen.uniform() - 1.0;
      continue;
    }
    const double lo = -0.5 - margin, hi = static_cast<double>(size) - 0.5 + margin;
    const double cell = std::floor(lo + (hi - lo) * gen.uniform());
    const double px = cell + 0.02 + 0.96 * gen.uniform();
    v[i] = align_corners ? px / static_cast<double>(size - 1) * 2.0 - 1.0
                         : (2.0 * px + 1.0) / static_cast<double>(size) - 1.0;
  }
  return pair_of(v, {n, oh, ow, 2});
}

Calls grid_sample_calls() {
  struct Case {
    Shape x;  // N, C, H, W
    int64_t oh, ow;
  };
  const Case cases[] = {
      {{2, 3, 7, 9}, 5, 6},     {{1, 2, 1, 1}, 4, 3},     {{2, 1, 1, 5}, 3, 3},
      {{1, 4, 6, 1}, 2, 7},     {{2, 3, 6, 7}, 5, 4},     {{2, 16, 48, 64}, 40, 56},
      {{1, 1, 30, 40}, 50, 60}, {{8, 2, 20, 24}, 20, 24},
  };
  Generator gen(10);
  Calls calls;
  for (const Case& c : cases) {
    for (GridPadding pad : {GridPadding::zeros, GridPadding::border}) {
      for (bool ac : {false, true}) {
        const std::string what =
            shape_text(c.x) + " grid " + std::to_string(c.oh) + "x" + std::to_string(c.ow) +
            (pad == GridPadding::zeros ? " zeros" : " border") + (ac ? " align_corners" : "");
        const auto p = params_of(GridSampleParams{pad, ac});
        const Pair x = normal(c.x, gen);
        const Pair grid = sample_grid(c.x[0], c.oh, c.ow, c.x[2], c.x[3], ac, 2.0, gen);
        const Shape out = {c.x[0], c.x[1], c.oh, c.ow};
        calls.push_back({"grid_sample " + what, OpId::grid_sample, {x, grid}, {out}, p, 1e-5});
        calls.push_back({"grid_sample backward " + what,
                         OpId::grid_sample_backward,
                         {normal(out, gen), x, grid},
                         {c.x, grid.t64.shape()},
                         p,
                         1e-5});
        calls.push_back({"grid_sample backward, grid only " + what,
                         OpId::grid_sample_backward,
                         {normal(out, gen), x, grid},
                         {kUndefined, grid.t64.shape()},
                         p,
                         1e-5});
      }
    }
  }
  return calls;
}

// ---- normalisation and pooling ------------------------------------------------------------------

Calls batch_norm_calls() {
  Generator gen(8);
  Calls calls;
  const Shape c{4};
  // No activation, then relu and clip fused (BatchNormParams::fused_act; x spread so that clip
  // cuts on both sides).
  std::vector<std::optional<UnaryParams>> acts = {std::nullopt, UnaryParams{UnaryOp::relu},
                                                  UnaryParams{UnaryOp::clip, -0.5, 1.0}};
  // Three values per channel (two would make every input gradient 0), and 2 * 3 * 40 * 50 = 12000
  // per channel: several chunks.
  for (const Shape& s : {Shape{3, 4, 5, 6}, Shape{3, 4, 1, 1}, Shape{2, 4, 3, 40, 50}}) {
    for (const auto& act : acts) {
      for (bool training : {true, false}) {
        for (bool affine : {true, false}) {
          BatchNormParams bn;
          bn.training = training;
          bn.fused_act = act.has_value();
          if (act) bn.act = *act;
          const auto p = params_of(bn);
          const std::string what = shape_text(s) + (training ? " train" : " eval") +
                                   (affine ? " affine" : "") +
                                   (!act                       ? ""
                                    : act->op == UnaryOp::relu ? " relu"
                                                               : " clip");
          const Pair x = normal(s, gen, 2.0);
          const Pair gamma = affine ? uniform(c, gen, 0.5, 1.5) : Pair{};
          const Pair beta = affine ? normal(c, gen) : Pair{};
          const std::vector<Pair> in = {x, gamma, beta, normal(c, gen), uniform(c, gen, 0.5, 2.0)};
          // Reads the running statistics after the call too (updated in training).
          KernelCall fwd{"batch_norm " + what, OpId::batch_norm, in, {s, c, c}, p, 1e-5};
          fwd.read_inputs = true;
          calls.push_back(fwd);
          const auto ref = reference_outputs(OpId::batch_norm, in, {s, c, c}, p.get());
          const Pair mean = pair_of(ref.at(1), c), invstd = pair_of(ref.at(2), c);
          std::vector<Pair> bwd_in = {normal(s, gen), x, gamma, mean, invstd};
          if (act) bwd_in.push_back(beta);
          calls.push_back(
              {"batch_norm backward " + what, OpId::batch_norm_backward, bwd_in,
               affine ? std::vector<Shape>{s, c, c} : std::vector<Shape>{s, kUndefined, kUndefined},
               p, 1e-5});
        }
      }
    }
  }
  return calls;
}

int64_t pool_out(int64_t in, int k, int s, int pb, int pa, bool ceil_mode) {
  const int64_t span = in + pb + pa - k;
  int64_t o = (ceil_mode ? (span + s - 1) / s : span / s) + 1;
  if (ceil_mode && (o - 1) * s >= in + pb) --o;  // PyTorch: the last window starts inside
  return o;
}

Calls pool_calls() {
  std::vector<std::pair<Pool2dParams, Shape>> cases;
  Pool2dParams p;
  cases.push_back({p, {2, 3, 8, 9}});
  p.kernel_h = 3, p.kernel_w = 3, p.stride_h = 2, p.stride_w = 2, p.pad_top = 1, p.pad_left = 1;
  p.pad_bottom = 1, p.pad_right = 1;
  cases.push_back({p, {1, 2, 9, 10}});
  cases.push_back({p, {2, 64, 48, 64}});  // a ResNet stem's pooling, many channels
  p.ceil_mode = true;
  p.count_include_pad = false;
  cases.push_back({p, {1, 2, 10, 7}});
  p.kernel_h = 2, p.kernel_w = 3, p.stride_h = 1, p.stride_w = 2, p.pad_top = 0, p.pad_left = 1;
  p.pad_bottom = 0, p.pad_right = 1, p.ceil_mode = false, p.count_include_pad = true;
  cases.push_back({p, {2, 1, 6, 7}});
  Generator gen(9);
  Calls calls;
  for (const auto& [q, xs] : cases) {
    const Shape y{xs[0], xs[1],
                  pool_out(xs[2], q.kernel_h, q.stride_h, q.pad_top, q.pad_bottom, q.ceil_mode),
                  pool_out(xs[3], q.kernel_w, q.stride_w, q.pad_left, q.pad_right, q.ceil_mode)};
    const std::string what = shape_text(xs) + " -> " + shape_text(y);
    const auto params = params_of(q);
    const Pair x = normal(xs, gen);
    calls.push_back({"max_pool " + what, OpId::max_pool2d, {x}, {y}, params, 0.0});
    calls.push_back({"max_pool backward " + what,
                     OpId::max_pool2d_backward,
                     {normal(y, gen), x},
                     {xs},
                     params,
                     1e-6});
    calls.push_back({"avg_pool " + what, OpId::avg_pool2d, {x}, {y}, params, 1e-6});
    calls.push_back({"avg_pool backward " + what,
                     OpId::avg_pool2d_backward,
                     {normal(y, gen)},
                     {xs},
                     params,
                     1e-6});
  }
  return calls;
}

// ---- convolutions -------------------------------------------------------------------------------

Calls conv2d_calls() {
  Generator gen(10);
  Calls calls;
  {  // strided, asymmetric padding, dilated along w, grouped
    Conv2dParams c;
    c.stride_h = 2, c.stride_w = 1, c.pad_top = 1, c.pad_bottom = 2, c.pad_left = 0;
    c.pad_right = 1, c.dilation_h = 1, c.dilation_w = 2, c.groups = 2;
    const auto p = params_of(c);
    const Shape x{2, 4, 9, 8}, w{6, 2, 3, 3};
    const Shape y{2, 6, (9 + 1 + 2 - 1 * (3 - 1) - 1) / 2 + 1, (8 + 0 + 1 - 2 * (3 - 1) - 1) + 1};
    const Pair xv = normal(x, gen), wv = normal(w, gen), gy = normal(y, gen);
    calls.push_back({"conv2d", OpId::conv2d, {xv, wv, normal({6}, gen)}, {y}, p, 1e-5});
    calls.push_back({"conv2d without bias", OpId::conv2d, {xv, wv, Pair{}}, {y}, p, 1e-5});
    calls.push_back({"conv2d backward data", OpId::conv2d_backward_data, {gy, wv}, {x}, p, 1e-5});
    calls.push_back(
        {"conv2d backward weight", OpId::conv2d_backward_weight, {gy, xv}, {w, {6}}, p, 1e-5});
  }
  {  // N * OH = 140 output rows of OW = 90: CUDA sums the weight gradient in chunks of rows
    Conv2dParams c;
    c.pad_top = c.pad_bottom = c.pad_left = c.pad_right = 1;
    const Shape x{2, 3, 70, 90}, w{4, 3, 3, 3}, y{2, 4, 70, 90};
    calls.push_back({"conv2d backward weight, many rows",
                     OpId::conv2d_backward_weight,
                     {normal(y, gen), normal(x, gen)},
                     {w, {4}},
                     params_of(c),
                     1e-5});
  }
  {  // 1x1, one pixel
    const Shape x{3, 5, 1, 1}, w{7, 5, 1, 1}, y{3, 7, 1, 1};
    const auto p = params_of(Conv2dParams{});
    const Pair xv = normal(x, gen), wv = normal(w, gen), gy = normal(y, gen);
    calls.push_back(
        {"conv2d 1x1 one pixel", OpId::conv2d, {xv, wv, normal({7}, gen)}, {y}, p, 1e-5});
    calls.push_back(
        {"conv2d 1x1 backward data", OpId::conv2d_backward_data, {gy, wv}, {x}, p, 1e-5});
    calls.push_back(
        {"conv2d 1x1 backward weight", OpId::conv2d_backward_weight, {gy, xv}, {w, {7}}, p, 1e-5});
  }
  return calls;
}

Calls conv_transpose2d_calls() {
  Generator gen(11);
  ConvTranspose2dParams c;
  c.stride_h = 2, c.stride_w = 3, c.pad_top = 1, c.pad_bottom = 0, c.pad_left = 1;
  c.pad_right = 2, c.output_padding_h = 1, c.output_padding_w = 0, c.dilation_h = 2;
  c.dilation_w = 1, c.groups = 2;
  const auto p = params_of(c);
  const Shape x{2, 4, 5, 4}, w{4, 3, 3, 2};
  const Shape y{2, 6, (5 - 1) * 2 - 1 - 0 + 2 * (3 - 1) + 1 + 1,
                (4 - 1) * 3 - 1 - 2 + 1 * (2 - 1) + 0 + 1};
  const Pair xv = normal(x, gen), wv = normal(w, gen), gy = normal(y, gen);
  return {
      {"conv_transpose2d", OpId::conv_transpose2d, {xv, wv, normal({6}, gen)}, {y}, p, 1e-5},
      {"conv_transpose2d backward data",
       OpId::conv_transpose2d_backward_data,
       {gy, wv},
       {x},
       p,
       1e-5},
      {"conv_transpose2d backward weight",
       OpId::conv_transpose2d_backward_weight,
       {gy, xv},
       {w, {6}},
       p,
       1e-5},
  };
}

// ---- correlation / channel norm (FlowNet2) ------------------------------------------------------

Calls correlation_calls() {
  Generator gen(12);
  Calls calls;
  const std::pair<CorrelationParams, Shape> cases[] = {{{4, 1, 4, 1, 2}, {1, 3, 9, 10}},
                                                       {{2, 3, 2, 2, 1}, {2, 2, 11, 9}}};
  for (const auto& [c, in] : cases) {
    const Shape y{in[0], int64_t{c.displacement_size()} * c.displacement_size(), c.out_size(in[2]),
                  c.out_size(in[3])};
    const std::string what = "correlation k" + std::to_string(c.kernel_size);
    const Pair a = normal(in, gen), b = normal(in, gen);
    calls.push_back({what, OpId::correlation, {a, b}, {y}, params_of(c), 1e-5});
    calls.push_back({what + " backward",
                     OpId::correlation_backward,
                     {normal(y, gen), a, b},
                     {in, in},
                     params_of(c),
                     1e-5});
  }
  return calls;
}

Calls channel_norm_calls() {
  Generator gen(13);
  Calls calls;
  for (const Shape& x : {Shape{2, 5, 4, 3}, Shape{1, 2, 30, 40}}) {
    const Shape y{x[0], 1, x[2], x[3]};
    const Pair xv = normal(x, gen);
    const Pair yv = pair_of(reference_outputs(OpId::channel_norm, {xv}, {y}, nullptr).at(0), y);
    calls.push_back(
        {"channel_norm " + shape_text(x), OpId::channel_norm, {xv}, {y}, nullptr, 1e-6});
    calls.push_back({"channel_norm backward " + shape_text(x),
                     OpId::channel_norm_backward,
                     {normal(y, gen), xv, yv},
                     {x},
                     nullptr,
                     1e-6});
  }
  return calls;
}

}  // namespace

std::vector<KernelCase> spatial_kernel_cases() {
  return {{"upsample_bilinear2d", bilinear_calls},
          {"upsample_bicubic2d", bicubic_calls},
          {"upsample_nearest2d", nearest_calls},
          {"grid_sample", grid_sample_calls},
          {"batch_norm", batch_norm_calls},
          {"pool2d", pool_calls},
          {"conv2d", conv2d_calls},
          {"conv_transpose2d", conv_transpose2d_calls},
          {"correlation", correlation_calls},
          {"channel_norm", channel_norm_calls}};
}

}  // namespace cvd::test
