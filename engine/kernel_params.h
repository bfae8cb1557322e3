// Parameter structs of the kernels in the dispatch table (engine/dispatch.h). Shared by the op
// layer, every backend and the tests. The element-wise ops (UnaryOp, BinaryOp, their parameters
// and math) are in engine/elementwise_math.h; resampling coordinates in engine/resample_math.h.
#pragma once
#include <cstdint>
#include <vector>

#include "engine/elementwise_math.h"

namespace cvd {

struct FillParams {
  double value = 0.0;
};

// Sums x over `dims` (sorted, unique, non-negative). Output has the reduced dims removed.
struct ReduceParams {
  std::vector<int> dims;
};

struct ConcatParams {
  int dim = 0;
};

// Constant padding, per dimension, non-negative amounts; before.size() == after.size() == ndim.
struct PadParams {
  std::vector<int64_t> before;
  std::vector<int64_t> after;
  double value = 0.0;
};

struct Conv2dParams {
  int stride_h = 1, stride_w = 1;
  int pad_top = 0, pad_bottom = 0, pad_left = 0, pad_right = 0;
  int dilation_h = 1, dilation_w = 1;
  int groups = 1;
};

// Weight layout [C_in, C_out / groups, kh, kw] as PyTorch. Output size per dim:
// (in - 1) * stride - pad_before - pad_after + dilation * (k - 1) + output_padding + 1.
struct ConvTranspose2dParams {
  int stride_h = 1, stride_w = 1;
  int pad_top = 0, pad_bottom = 0, pad_left = 0, pad_right = 0;
  int output_padding_h = 0, output_padding_w = 0;
  int dilation_h = 1, dilation_w = 1;
  int groups = 1;
};

// Training: normalise with batch statistics (biased variance), write them as outputs (mean,
// invstd = 1/sqrt(var + eps)), and update running stats in place:
// r = (1 - momentum) r + momentum * batch (running var uses the unbiased variance).
// Eval: normalise with running stats; outputs mean = running mean, invstd from running var.
struct BatchNormParams {
  bool training = true;
  double momentum = 0.1;
  double eps = 1e-5;
  // An activation fused after the affine (relu or clip only; engine/ops.h batch_norm_act).
  // batch_norm then writes act(y); batch_norm_backward takes beta? as a sixth input, recomputes
  // the pre-activation y from x and the statistics, and passes gy only where act passes it.
  bool fused_act = false;
  UnaryParams act;
};

struct Pool2dParams {
  int kernel_h = 2, kernel_w = 2;
  int stride_h = 2, stride_w = 2;
  int pad_top = 0, pad_bottom = 0, pad_left = 0, pad_right = 0;
  bool ceil_mode = false;
  bool count_include_pad = true;  // avg pool only (PyTorch default true)
};

// Output size is given by the output tensor. Source coordinate of output index o:
// align_corners: o * (in - 1) / (out - 1) (0 when out == 1); else (o + 0.5) * in / out - 0.5,
// clamped below at 0 (PyTorch). Nearest: floor(o * in / out) (PyTorch "nearest").
struct UpsampleParams {
  bool align_corners = false;
  // Bicubic only: the scale factor PyTorch's interpolate was given (scale_factor=, not size=), which
  // then sets the source coordinate (o + 0.5) / scale - 0.5 instead of (o + 0.5) * in / out - 0.5
  // (align_corners false); 0 = none. Ignored with align_corners.
  double scale_h = 0.0, scale_w = 0.0;
};

// Layer norm over the last dimension of x viewed as [rows, C] (PyTorch LayerNorm(C, eps)):
// y = (x - mean) * invstd * gamma + beta, invstd = 1 / sqrt(var + eps), biased variance; the
// forward writes mean and invstd per row for the backward.
struct LayerNormParams {
  double eps = 1e-5;
};

struct MatmulParams {
  bool trans_a = false;  // use a^T (a stored [B,K,M])
  bool trans_b = false;  // use b^T (b stored [B,N,K])
};

enum class GridPadding : int { zeros, border };
// grid [N, Ho, Wo, 2] holds (x, y) in [-1, 1]; bilinear interpolation as PyTorch grid_sample.
struct GridSampleParams {
  GridPadding padding = GridPadding::zeros;
  bool align_corners = false;
};

// PyTorch Adam (not AdamW): g += wd * p; m = b1 m + (1-b1) g; v = b2 v + (1-b2) g^2;
// p -= lr * (m / (1 - b1^t)) / (sqrt(v / (1 - b2^t)) + eps).
struct AdamParams {
  double lr = 1e-3, beta1 = 0.9, beta2 = 0.999, eps = 1e-8, weight_decay = 0.0;
  int64_t step = 1;  // t, already incremented
};

// PyTorch SGD: g += wd * p; buf = first ? g : momentum * buf + (1 - dampening) g;
// g = nesterov ? g + momentum * buf : buf (when momentum != 0); p -= lr * g.
struct SgdParams {
  double lr = 1e-2, momentum = 0.0, dampening = 0.0, weight_decay = 0.0;
  bool nesterov = false;
  bool first_step = true;
};

// FlowNetC correlation (flownet2-pytorch Correlation(pad_size, kernel_size, max_displacement,
// stride1, stride2)) of a, b [N, C, H, W] -> [N, D*D, Ho, Wo] with r = max_displacement / stride2,
// D = 2r + 1, k = kernel_size (odd), kr = (k - 1) / 2, border = max_displacement + kr,
// Ho = ceil((H + 2 pad - 2 border) / stride1) (likewise Wo). With the patch centre
// (y, x) = (oy * stride1 + border - pad, ox * stride1 + border - pad):
//   y[n, (tj + r) * D + (ti + r), oy, ox] = 1 / (k^2 C) * sum_{c, |dj|, |di| <= kr}
//       a[n, c, y + dj, x + di] * b[n, c, y + dj + tj * stride2, x + di + ti * stride2]
// for ti, tj in [-r, r]; reads outside the image are 0 (zero padding). For kernel_size 1 (the
// only size FlowNet2 uses) this is flownet2-pytorch's CUDA kernel exactly; for k > 1 the patch
// is centred at border as in the original Caffe layer (flownet2-pytorch centres it kr earlier).
struct CorrelationParams {
  int pad = 0;
  int kernel_size = 1;
  int max_displacement = 1;
  int stride1 = 1;
  int stride2 = 1;
  int displacement_radius() const { return max_displacement / stride2; }
  int displacement_size() const { return 2 * displacement_radius() + 1; }
  int kernel_radius() const { return (kernel_size - 1) / 2; }
  int border() const { return max_displacement + kernel_radius(); }
  // Output size along one dim of input size `in` (ceil division as flownet2-pytorch).
  int64_t out_size(int64_t in) const {
    const int64_t span = in + 2 * static_cast<int64_t>(pad) - 2 * static_cast<int64_t>(border());
    return span <= 0 ? 0 : (span + stride1 - 1) / stride1;
  }
};

}  // namespace cvd
