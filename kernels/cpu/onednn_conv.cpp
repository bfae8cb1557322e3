// conv2d, conv2d_backward_data and conv2d_backward_weight (with the bias gradient) on oneDNN
// convolution primitives: NCHW caller tensors, PyTorch weight layout [O, C/g, KH, KW],
// asymmetric padding, dilation and groups. Depthwise convolutions go to the hand-written kernel
// of depthwise_conv2d.h and pointwise ones to matmul primitives (onednn_pointwise_conv.cpp).
#include <cstring>

#include "engine/error.h"
#include "engine/kernel_params.h"
#include "kernels/cpu/cpu_parallel.h"
#include "kernels/cpu/depthwise_conv2d.h"
#include "kernels/cpu/narrow_conv2d.h"
#include "kernels/cpu/onednn_context.h"
#include "kernels/cpu/onednn_conv_family.h"
#include "kernels/cpu/onednn_kernels.h"

namespace cvd::onednn {

namespace {

using tag = dnnl::memory::format_tag;

// x [N, C, H, W], w [O, C/g, KH, KW], y [N, O, OH, OW].
ConvProblem conv_problem(const Shape& x, const Shape& w, const Shape& y, const Conv2dParams& p,
                         bool bias) {
  ConvProblem pr;
  pr.src = {x[0], x[1], x[2], x[3]};
  pr.dst = {y[0], y[1], y[2], y[3]};
  pr.groups = p.groups;
  if (p.groups == 1) {
    pr.weights = {w[0], w[1], w[2], w[3]};
    pr.weights_tag = tag::oihw;
  } else {
    pr.weights = {p.groups, w[0] / p.groups, w[1], w[2], w[3]};
    pr.weights_tag = tag::goihw;
  }
  pr.strides = {p.stride_h, p.stride_w};
  pr.dilates = {p.dilation_h - 1, p.dilation_w - 1};
  pr.pad_l = {p.pad_top, p.pad_left};
  pr.pad_r = {p.pad_bottom, p.pad_right};
  pr.bias = bias;
  choose_conv_precision(pr);
  return pr;
}

// The hand-written depthwise kernel's view of x [N, C, H, W] -> y [N, C, OH, OW], w [C, 1, KH, KW].
cpu::DepthwiseGeometry depthwise_geometry(const Shape& x, const Shape& w, const Shape& y,
                                          const Conv2dParams& p) {
  cpu::DepthwiseGeometry g;
  g.n = x[0], g.c = x[1], g.h = x[2], g.w = x[3], g.oh = y[2], g.ow = y[3];
  g.kh = w[2], g.kw = w[3];
  g.stride_h = p.stride_h, g.stride_w = p.stride_w, g.pad_top = p.pad_top, g.pad_left = p.pad_left;
  g.dil_h = p.dilation_h, g.dil_w = p.dilation_w;
  return g;
}

// The few-output-channel kernel's view of x [N, C, H, W] -> y [N, O, OH, OW], w [O, C, KH, KW].
cpu::NarrowConvGeometry narrow_geometry(const Shape& x, const Shape& w, const Shape& y,
                                        const Conv2dParams& p) {
  cpu::NarrowConvGeometry g;
  g.n = x[0], g.c = x[1], g.h = x[2], g.w = x[3], g.o = y[1], g.oh = y[2], g.ow = y[3];
  g.kh = w[2], g.kw = w[3], g.pad_top = p.pad_top, g.pad_left = p.pad_left;
  return g;
}

// w [O, C, KH, KW] -> [C, O, KH, KW], each filter turned by 180 degrees.
Tensor flipped_transposed_weights(const Tensor& w) {
  const Shape& s = w.shape();
  const int64_t O = s[0], C = s[1], KH = s[2], KW = s[3];
  Tensor f = Tensor::empty({C, O, KH, KW});
  const float* src = w.data<float>();
  float* dst = f.data<float>();
  for (int64_t o = 0; o < O; ++o)
    for (int64_t c = 0; c < C; ++c)
      for (int64_t y = 0; y < KH; ++y)
        for (int64_t x = 0; x < KW; ++x)
          dst[((c * O + o) * KH + (KH - 1 - y)) * KW + (KW - 1 - x)] =
              src[((o * C + c) * KH + y) * KW + x];
  return f;
}

// in {x, w, b?}, out {y}; Conv2dParams.
void conv2d(const KernelArgs& a) {
  const Tensor &x = a.in[0], &w = a.in[1], &b = a.in[2], &y = a.out[0];
  check_f32_4d(x, "kernels/cpu/onednn_conv.cpp", "conv2d input");
  check_f32_4d(w, "kernels/cpu/onednn_conv.cpp", "conv2d weight");
  check_f32_4d(y, "kernels/cpu/onednn_conv.cpp", "conv2d output");
  if (y.numel() == 0) return;
  const ConvProblem pr =
      conv_problem(x.shape(), w.shape(), y.shape(), a.p<Conv2dParams>(), b.defined());
  if (use_depthwise_kernel(pr, ConvPass::forward)) {
    cpu::depthwise_conv2d_forward(
        depthwise_geometry(x.shape(), w.shape(), y.shape(), a.p<Conv2dParams>()), x.data<float>(),
        w.data<float>(), b.defined() ? b.data<float>() : nullptr, y.data<float>());
    return;
  }
  if (use_pointwise_matmul(pr)) {
    pointwise_conv_forward(x, w, b, y);
    return;
  }
  if (use_narrow_conv_kernel(pr)) {
    cpu::narrow_conv2d_forward(
        narrow_geometry(x.shape(), w.shape(), y.shape(), a.p<Conv2dParams>()), x.data<float>(),
        w.data<float>(), b.defined() ? b.data<float>() : nullptr, y.data<float>());
    return;
  }
  ChunkedPrimitive& plan = conv_pass_plan<ConvolutionFamily>(pr, ConvPass::forward);
  if (b.defined()) {
    plan.execute({x, w, b, y});
  } else {
    plan.execute({x, w, y});
  }
}

// in {gy, w}, out {gx}; Conv2dParams.
void conv2d_backward_data(const KernelArgs& a) {
  const Tensor &gy = a.in[0], &w = a.in[1], &gx = a.out[0];
  check_f32_4d(gy, "kernels/cpu/onednn_conv.cpp", "conv2d_backward_data output gradient");
  check_f32_4d(w, "kernels/cpu/onednn_conv.cpp", "conv2d_backward_data weight");
  check_f32_4d(gx, "kernels/cpu/onednn_conv.cpp", "conv2d_backward_data input gradient");
  if (gx.numel() == 0) return;
  const ConvProblem pr =
      conv_problem(gx.shape(), w.shape(), gy.shape(), a.p<Conv2dParams>(), false);
  if (use_depthwise_kernel(pr, ConvPass::backward_data)) {
    cpu::depthwise_conv2d_backward_data(
        depthwise_geometry(gx.shape(), w.shape(), gy.shape(), a.p<Conv2dParams>()),
        gy.data<float>(), w.data<float>(), gx.data<float>());
    return;
  }
  if (use_pointwise_matmul(pr)) {
    pointwise_conv_backward_data(gy, w, gx);
    return;
  }
  if (use_backward_data_as_forward(pr)) {
    const Tensor wf = flipped_transposed_weights(w);
    Conv2dParams fp = a.p<Conv2dParams>();
    const int kh = static_cast<int>(w.shape()[2]), kw = static_cast<int>(w.shape()[3]);
    fp.pad_top = kh - 1 - fp.pad_top;
    fp.pad_bottom = kh - 1 - fp.pad_bottom;
    fp.pad_left = kw - 1 - fp.pad_left;
    fp.pad_right = kw - 1 - fp.pad_right;
    const ConvProblem fpr = conv_problem(gy.shape(), wf.shape(), gx.shape(), fp, false);
    if (use_narrow_conv_kernel(fpr)) {
      cpu::narrow_conv2d_forward(narrow_geometry(gy.shape(), wf.shape(), gx.shape(), fp),
                                 gy.data<float>(), wf.data<float>(), nullptr, gx.data<float>());
      return;
    }
    conv_pass_plan<ConvolutionFamily>(fpr, ConvPass::forward).execute({gy, wf, gx});
    return;
  }
  conv_pass_plan<ConvolutionFamily>(pr, ConvPass::backward_data).execute({gy, w, gx});
}

// in {gy, x}, out {gw, gb?}; Conv2dParams.
void conv2d_backward_weight(const KernelArgs& a) {
  const Tensor &gy = a.in[0], &x = a.in[1], &gw = a.out[0], &gb = a.out[1];
  check_f32_4d(gy, "kernels/cpu/onednn_conv.cpp", "conv2d_backward_weight output gradient");
  check_f32_4d(x, "kernels/cpu/onednn_conv.cpp", "conv2d_backward_weight input");
  check_f32_4d(gw, "kernels/cpu/onednn_conv.cpp", "conv2d_backward_weight weight gradient");
  if (x.shape()[0] == 0) {
    zero_fill(gw);
    zero_fill(gb);
    return;
  }
  ConvProblem pr =
      conv_problem(x.shape(), gw.shape(), gy.shape(), a.p<Conv2dParams>(), gb.defined());
  pr.bf16 = bf16_backward_weights(pr);
  if (use_depthwise_kernel(pr, ConvPass::backward_weights)) {
    cpu::depthwise_conv2d_backward_weight(
        depthwise_geometry(x.shape(), gw.shape(), gy.shape(), a.p<Conv2dParams>()),
        gy.data<float>(), x.data<float>(), gw.data<float>(),
        gb.defined() ? gb.data<float>() : nullptr);
    return;
  }
  if (use_pointwise_matmul(pr)) {
    pointwise_conv_backward_weight(gy, x, gw, gb);
    return;
  }
  if (use_narrow_conv_kernel(pr)) {
    cpu::narrow_conv2d_backward_weight(
        narrow_geometry(x.shape(), gw.shape(), gy.shape(), a.p<Conv2dParams>()), gy.data<float>(),
        x.data<float>(), gw.data<float>());
    if (gb.defined()) bias_gradient_nchw(gy, gb);
    return;
  }
  run_conv_backward_weights<ConvolutionFamily>(pr, x, gy, gw, gb);
}

}  // namespace

void zero_fill(const Tensor& t) {
  if (t.defined() && t.numel() > 0) std::memset(t.data_ptr(), 0, t.nbytes());
}

void bias_gradient_nchw(const Tensor& gy, const Tensor& gb) {
  const int64_t n = gy.shape()[0], c = gy.shape()[1], hw = gy.shape()[2] * gy.shape()[3];
  const float* g = gy.data<float>();
  float* out = gb.data<float>();
  cpu::parallel_ranges(c, n * hw, [&](int64_t begin, int64_t end) {
    for (int64_t ch = begin; ch < end; ++ch) {
      double sum = 0;
      for (int64_t i = 0; i < n; ++i) {
        const float* row = g + (i * c + ch) * hw;
        float part = 0;
        for (int64_t k = 0; k < hw; ++k) part += row[k];
        sum += part;
      }
      out[ch] = static_cast<float>(sum);
    }
  });
}

void register_conv_kernels(KernelRegistry& r) {
  r.add(OpId::conv2d, DeviceType::cpu, DType::f32, guarded<OpId::conv2d, conv2d>, "onednn");
  r.add(OpId::conv2d_backward_data, DeviceType::cpu, DType::f32,
        guarded<OpId::conv2d_backward_data, conv2d_backward_data>, "onednn");
  r.add(OpId::conv2d_backward_weight, DeviceType::cpu, DType::f32,
        guarded<OpId::conv2d_backward_weight, conv2d_backward_weight>, "onednn");
}

}  // namespace cvd::onednn
