// conv_transpose2d and its backward passes on oneDNN deconvolution primitives: NCHW caller
// tensors, PyTorch weight layout [C_in, C_out/g, KH, KW] (oneDNN's iohw / giohw), asymmetric
// padding, output_padding (a smaller, possibly negative, right padding), dilation and groups.
#include <cstring>

#include "engine/error.h"
#include "engine/kernel_params.h"
#include "kernels/cpu/onednn_context.h"
#include "kernels/cpu/onednn_conv_family.h"
#include "kernels/cpu/onednn_kernels.h"

namespace cvd::onednn {

namespace {

using tag = dnnl::memory::format_tag;

// x [N, C_in, H, W], w [C_in, C_out/g, KH, KW], y [N, C_out, OH, OW]. oneDNN's deconvolution
// output size is (H - 1) * s - pad_l - pad_r + d * (k - 1) + 1, so output_padding enters as
// pad_r = pad_after - output_padding.
ConvProblem deconv_problem(const Shape& x, const Shape& w, const Shape& y,
                           const ConvTranspose2dParams& p, bool bias) {
  ConvProblem pr;
  pr.src = {x[0], x[1], x[2], x[3]};
  pr.dst = {y[0], y[1], y[2], y[3]};
  pr.groups = p.groups;
  if (p.groups == 1) {
    pr.weights = {w[1], w[0], w[2], w[3]};
    pr.weights_tag = tag::iohw;
  } else {
    pr.weights = {p.groups, w[1], w[0] / p.groups, w[2], w[3]};
    pr.weights_tag = tag::giohw;
  }
  pr.strides = {p.stride_h, p.stride_w};
  pr.dilates = {p.dilation_h - 1, p.dilation_w - 1};
  pr.pad_l = {p.pad_top, p.pad_left};
  pr.pad_r = {p.pad_bottom - p.output_padding_h, p.pad_right - p.output_padding_w};
  pr.bias = bias;
  choose_conv_precision(pr);
  return pr;
}

// in {x, w, b?}, out {y}; ConvTranspose2dParams.
void conv_transpose2d(const KernelArgs& a) {
  const Tensor &x = a.in[0], &w = a.in[1], &b = a.in[2], &y = a.out[0];
  check_f32_4d(x, "kernels/cpu/onednn_deconv.cpp", "conv_transpose2d input");
  check_f32_4d(w, "kernels/cpu/onednn_deconv.cpp", "conv_transpose2d weight");
  check_f32_4d(y, "kernels/cpu/onednn_deconv.cpp", "conv_transpose2d output");
  if (y.numel() == 0) return;
  const ConvProblem pr =
      deconv_problem(x.shape(), w.shape(), y.shape(), a.p<ConvTranspose2dParams>(), b.defined());
  ChunkedPrimitive& plan = conv_pass_plan<DeconvolutionFamily>(pr, ConvPass::forward);
  if (b.defined()) {
    plan.execute({x, w, b, y});
  } else {
    plan.execute({x, w, y});
  }
}

// in {gy, w}, out {gx}.
void conv_transpose2d_backward_data(const KernelArgs& a) {
  const Tensor &gy = a.in[0], &w = a.in[1], &gx = a.out[0];
  check_f32_4d(gy, "kernels/cpu/onednn_deconv.cpp",
               "conv_transpose2d_backward_data output gradient");
  check_f32_4d(w, "kernels/cpu/onednn_deconv.cpp", "conv_transpose2d_backward_data weight");
  check_f32_4d(gx, "kernels/cpu/onednn_deconv.cpp",
               "conv_transpose2d_backward_data input gradient");
  if (gx.numel() == 0) return;
  const ConvProblem pr =
      deconv_problem(gx.shape(), w.shape(), gy.shape(), a.p<ConvTranspose2dParams>(), false);
  conv_pass_plan<DeconvolutionFamily>(pr, ConvPass::backward_data).execute({gy, w, gx});
}

// in {gy, x}, out {gw, gb?}.
void conv_transpose2d_backward_weight(const KernelArgs& a) {
  const Tensor &gy = a.in[0], &x = a.in[1], &gw = a.out[0], &gb = a.out[1];
  check_f32_4d(gy, "kernels/cpu/onednn_deconv.cpp",
               "conv_transpose2d_backward_weight output gradient");
  check_f32_4d(x, "kernels/cpu/onednn_deconv.cpp", "conv_transpose2d_backward_weight input");
  check_f32_4d(gw, "kernels/cpu/onednn_deconv.cpp",
               "conv_transpose2d_backward_weight weight gradient");
  if (x.shape()[0] == 0) {
    zero_fill(gw);
    zero_fill(gb);
    return;
  }
  const ConvProblem pr =
      deconv_problem(x.shape(), gw.shape(), gy.shape(), a.p<ConvTranspose2dParams>(), gb.defined());
  run_conv_backward_weights<DeconvolutionFamily>(pr, x, gy, gw, gb);
}

}  // namespace

void register_deconv_kernels(KernelRegistry& r) {
  r.add(OpId::conv_transpose2d, DeviceType::cpu, DType::f32,
        guarded<OpId::conv_transpose2d, conv_transpose2d>, "onednn");
  r.add(OpId::conv_transpose2d_backward_data, DeviceType::cpu, DType::f32,
        guarded<OpId::conv_transpose2d_backward_data, conv_transpose2d_backward_data>, "onednn");
  r.add(OpId::conv_transpose2d_backward_weight, DeviceType::cpu, DType::f32,
        guarded<OpId::conv_transpose2d_backward_weight, conv_transpose2d_backward_weight>,
        "onednn");
}

}  // namespace cvd::onednn
