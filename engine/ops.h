// The engine's differentiable ops. Every function records itself on the autograd tape when an
// input requires grad (and grad mode is on), allocates its output and runs the kernel of the
// dispatch table for the inputs' device and dtype. All inputs of one op must share device and
// dtype. Shapes are NCHW where images are concerned.
#pragma once
#include <vector>

#include "engine/kernel_params.h"
#include "engine/tensor.h"

namespace cvd {

// ---- Element-wise, unary -------------------------------------------------------------------
// Any op of engine/elementwise_math.h's list with its parameters; the named functions below are
// that call with the op's parameters spelled out.
Tensor unary(const Tensor& x, const UnaryParams& p);
inline Tensor relu(const Tensor& x) { return unary(x, {UnaryOp::relu}); }
inline Tensor relu6(const Tensor& x) { return unary(x, {UnaryOp::clip, 0.0, 6.0}); }
inline Tensor clamp(const Tensor& x, double lo, double hi) {
  return unary(x, {UnaryOp::clip, lo, hi});
}
inline Tensor leaky_relu(const Tensor& x, double negative_slope = 0.01) {
  return unary(x, {UnaryOp::leaky_relu, negative_slope});
}
inline Tensor sigmoid(const Tensor& x) { return unary(x, {UnaryOp::sigmoid}); }
inline Tensor tanh(const Tensor& x) { return unary(x, {UnaryOp::tanh}); }
inline Tensor exp(const Tensor& x) { return unary(x, {UnaryOp::exp}); }
inline Tensor log(const Tensor& x) { return unary(x, {UnaryOp::log}); }
inline Tensor abs(const Tensor& x) { return unary(x, {UnaryOp::abs}); }
inline Tensor sqrt(const Tensor& x) { return unary(x, {UnaryOp::sqrt}); }
inline Tensor neg(const Tensor& x) { return unary(x, {UnaryOp::neg}); }
inline Tensor reciprocal(const Tensor& x) { return unary(x, {UnaryOp::reciprocal}); }
inline Tensor pow(const Tensor& x, double exponent) {
  return unary(x, {UnaryOp::pow_scalar, exponent});
}
inline Tensor square(const Tensor& x) { return unary(x, {UnaryOp::pow_scalar, 2.0}); }
inline Tensor add_scalar(const Tensor& x, double s) { return unary(x, {UnaryOp::add_scalar, s}); }
inline Tensor mul_scalar(const Tensor& x, double s) { return unary(x, {UnaryOp::mul_scalar, s}); }
// gelu: the erf form (PyTorch's default); softplus: log(1 + e^x)
inline Tensor gelu(const Tensor& x) { return unary(x, {UnaryOp::gelu}); }
inline Tensor softplus(const Tensor& x) { return unary(x, {UnaryOp::softplus}); }

// ---- Element-wise, binary with NumPy broadcasting -------------------------------------------
Tensor add(const Tensor& a, const Tensor& b);
Tensor sub(const Tensor& a, const Tensor& b);
Tensor mul(const Tensor& a, const Tensor& b);
Tensor div(const Tensor& a, const Tensor& b);
Tensor minimum(const Tensor& a, const Tensor& b);  // gradient goes to a where a <= b
Tensor maximum(const Tensor& a, const Tensor& b);  // gradient goes to a where a >= b
// Comparisons: 1 where true, 0 elsewhere; never require grad.
Tensor gt(const Tensor& a, const Tensor& b);
Tensor ge(const Tensor& a, const Tensor& b);
Tensor lt(const Tensor& a, const Tensor& b);
Tensor le(const Tensor& a, const Tensor& b);
Tensor eq(const Tensor& a, const Tensor& b);
// cond != 0 ? a : b, broadcasting all three; differentiable in a and b.
Tensor where(const Tensor& cond, const Tensor& a, const Tensor& b);
Shape broadcast_shapes(const Shape& a, const Shape& b);

// ---- Reductions -----------------------------------------------------------------------------
// Empty dims = all dims. Negative dims count from the end.
Tensor sum(const Tensor& x, std::vector<int> dims = {}, bool keepdim = false);
Tensor mean(const Tensor& x, std::vector<int> dims = {}, bool keepdim = false);
// Sums a broadcast gradient back to `shape` (the inverse of broadcasting).
Tensor sum_to(const Tensor& x, const Shape& shape);

// ---- Shape and layout -----------------------------------------------------------------------
Tensor reshape(const Tensor& x, const Shape& shape);  // one dim may be -1
Tensor permute(const Tensor& x, const std::vector<int>& dims);
Tensor transpose(const Tensor& x, int a, int b);
Tensor squeeze(const Tensor& x, int dim);
Tensor unsqueeze(const Tensor& x, int dim);
Tensor narrow(const Tensor& x, int dim, int64_t start, int64_t length);
Tensor expand(const Tensor& x, const Shape& shape);
Tensor contiguous(const Tensor& x);
Tensor concat(const std::vector<Tensor>& xs, int dim);
// PyTorch F.pad order: pads = {last_before, last_after, second_last_before, ...}; constant value.
// Negative amounts crop.
Tensor pad(const Tensor& x, const std::vector<int64_t>& pads, double value = 0.0);

// ---- Neural-network ops (row normalisations: ops_rows.cpp) ------------------------------------
// x [N, C, H, W]; w [O, C/groups, kh, kw]; b [O] or undefined.
Tensor conv2d(const Tensor& x, const Tensor& w, const Tensor& b, const Conv2dParams& p);
// w [C, O/groups, kh, kw].
Tensor conv_transpose2d(const Tensor& x, const Tensor& w, const Tensor& b,
                        const ConvTranspose2dParams& p);
// gamma / beta may be undefined (affine=false). running stats are updated in place when
// training (they never require grad).
Tensor batch_norm(const Tensor& x, const Tensor& running_mean, const Tensor& running_var,
                  const Tensor& gamma, const Tensor& beta, const BatchNormParams& p);
// act(batch_norm(x)) for act = relu or clip (relu6), one recorded op that keeps x but not its
// output, and one kernel call each way (BatchNormParams::fused_act): the forward writes act(y),
// the backward masks gy at the pre-activation it recomputes from x. Convolutions that read the
// output recompute it instead of keeping it (engine/rematerialize.h).
Tensor batch_norm_act(const Tensor& x, const Tensor& running_mean, const Tensor& running_var,
                      const Tensor& gamma, const Tensor& beta, const BatchNormParams& p,
                      const UnaryParams& act);
Tensor max_pool2d(const Tensor& x, const Pool2dParams& p);
Tensor avg_pool2d(const Tensor& x, const Pool2dParams& p);
Tensor upsample_bilinear2d(const Tensor& x, int64_t out_h, int64_t out_w, bool align_corners);
Tensor upsample_nearest2d(const Tensor& x, int64_t out_h, int64_t out_w);
// PyTorch bicubic (A = -0.75). scale_h / scale_w > 0: the scale factors PyTorch's interpolate was
// given (scale_factor=), which set the source coordinates (see UpsampleParams); 0 = out / in.
Tensor upsample_bicubic2d(const Tensor& x, int64_t out_h, int64_t out_w, bool align_corners,
                          double scale_h = 0.0, double scale_w = 0.0);
// a [..., M, K] x b [..., K, N] with NumPy broadcasting of the batch dims ([..]); b 2-D is
// shared by every row of a.
Tensor matmul(const Tensor& a, const Tensor& b);
// x [..., in]; w [out, in]; b [out] or undefined.
Tensor linear(const Tensor& x, const Tensor& w, const Tensor& b);
// Over the last dimension (PyTorch LayerNorm(C, eps)); gamma / beta [C] or undefined.
Tensor layer_norm(const Tensor& x, const Tensor& gamma, const Tensor& beta, double eps = 1e-5);
// Over the last dimension, numerically stable (the row maximum subtracted first).
Tensor softmax(const Tensor& x);
// x [N, C, H, W]; grid [N, Ho, Wo, 2] -> [N, C, Ho, Wo].
Tensor grid_sample(const Tensor& x, const Tensor& grid, const GridSampleParams& p);

// ---- Optical flow (FlowNet2) -------------------------------------------------------------------
// FlowNetC correlation of a, b [N, C, H, W] -> [N, D*D, Ho, Wo] (definition: CorrelationParams).
Tensor correlation(const Tensor& a, const Tensor& b, const CorrelationParams& p);
// FlowNet2 ChannelNorm: sqrt(sum_c x^2), [N, C, H, W] -> [N, 1, H, W]. Its gradient x / norm is
// defined as 0 where the norm is 0.
Tensor channel_norm(const Tensor& x);

// Output spatial size of a convolution / pooling along one dim (floor or ceil mode).
int64_t conv_out_size(int64_t in, int k, int stride, int pad_before, int pad_after, int dilation);
int64_t pool_out_size(int64_t in, int k, int stride, int pad_before, int pad_after, bool ceil_mode);

}  // namespace cvd
