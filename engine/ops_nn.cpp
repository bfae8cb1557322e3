// Neural-network ops: convolutions, batch norm, pooling, resizing, matmul/linear, grid_sample.
// Each forward runs its kernel and records a backward that runs the matching backward kernels.
#include <cmath>

#include "engine/elementwise_math.h"
#include "engine/op_support.h"
#include "engine/rematerialize.h"

namespace cvd {

using detail::check_same_kind;
using detail::contiguous_or_undefined;
using detail::empty_like_kind;

int64_t conv_out_size(int64_t in, int k, int stride, int pb, int pa, int dilation) {
  return (in + pb + pa - static_cast<int64_t>(dilation) * (k - 1) - 1) / stride + 1;
}

int64_t pool_out_size(int64_t in, int k, int stride, int pb, int pa, bool ceil_mode) {
  int64_t span = in + pb + pa - k;
  int64_t out = (ceil_mode ? (span + stride - 1) / stride : span / stride) + 1;
  // PyTorch: the last window must start inside the input or the left padding.
  if (ceil_mode && (out - 1) * stride >= in + pb) --out;
  return out;
}

// ---- conv2d ------------------------------------------------------------------------------------
Tensor conv2d(const Tensor& x_in, const Tensor& w_in, const Tensor& b_in, const Conv2dParams& p) {
  check_same_kind("conv2d", x_in, w_in);
  check_same_kind("conv2d", x_in, b_in);
  CVD_CHECK(x_in.dim() == 4 && w_in.dim() == 4, "conv2d: x {} and w {} must be 4-d", x_in.str(),
            w_in.str());
  CVD_CHECK(
      p.groups >= 1 && x_in.size(1) == w_in.size(1) * p.groups && w_in.size(0) % p.groups == 0,
      "conv2d: x {} does not match weight {} with groups {}", x_in.str(), w_in.str(), p.groups);
  CVD_CHECK(!b_in.defined() || (b_in.dim() == 1 && b_in.size(0) == w_in.size(0)),
            "conv2d: bias {} does not match weight {}", b_in.str(), w_in.str());
  CVD_CHECK(p.stride_h >= 1 && p.stride_w >= 1 && p.dilation_h >= 1 && p.dilation_w >= 1,
            "conv2d: stride and dilation must be >= 1");
  Tensor x = x_in.contiguous(), w = w_in.contiguous(), b = contiguous_or_undefined(b_in);
  int64_t oh = conv_out_size(x.size(2), static_cast<int>(w.size(2)), p.stride_h, p.pad_top,
                             p.pad_bottom, p.dilation_h);
  int64_t ow = conv_out_size(x.size(3), static_cast<int>(w.size(3)), p.stride_w, p.pad_left,
                             p.pad_right, p.dilation_w);
  CVD_CHECK(oh > 0 && ow > 0, "conv2d: input {} too small for kernel {}", x.str(), w.str());
  Tensor y = empty_like_kind({x.size(0), w.size(0), oh, ow}, x);
  dispatch(OpId::conv2d, x, KernelArgs{{x, w, b}, {y}, &p});
  if (!any_requires_grad({x, w, b})) return y;
  return record("conv2d", y, {x, w, b},
                [xsaved = SavedTensor(x), xshape = x.shape(), ws = w.detach(), has_b = b.defined(),
                 p](const Tensor& g_in, const std::vector<bool>& need) {
                  Tensor g = g_in.contiguous();
                  Tensor gx, gw, gb;
                  if (need[0]) {
                    gx = empty_like_kind(xshape, ws);
                    dispatch(OpId::conv2d_backward_data, g, KernelArgs{{g, ws}, {gx}, &p});
                  }
                  if (need[1] || (has_b && need[2])) {
                    const Tensor xs = xsaved.get();
                    gw = empty_like_kind(ws.shape(), ws);
                    if (has_b && need[2]) gb = empty_like_kind({ws.size(0)}, ws);
                    dispatch(OpId::conv2d_backward_weight, g, KernelArgs{{g, xs}, {gw, gb}, &p});
                    if (!need[1]) gw = Tensor();
                  }
                  return std::vector<Tensor>{gx, gw, gb};
                });
}

// ---- conv_transpose2d ------------------------------------------------------------------------
Tensor conv_transpose2d(const Tensor& x_in, const Tensor& w_in, const Tensor& b_in,
                        const ConvTranspose2dParams& p) {
  check_same_kind("conv_transpose2d", x_in, w_in);
  check_same_kind("conv_transpose2d", x_in, b_in);
  CVD_CHECK(x_in.dim() == 4 && w_in.dim() == 4, "conv_transpose2d: x {} and w {} must be 4-d",
            x_in.str(), w_in.str());
  CVD_CHECK(p.groups >= 1 && x_in.size(1) == w_in.size(0) && w_in.size(0) % p.groups == 0,
            "conv_transpose2d: x {} does not match weight {} with groups {}", x_in.str(),
            w_in.str(), p.groups);
  int64_t oc = w_in.size(1) * p.groups;
  CVD_CHECK(!b_in.defined() || (b_in.dim() == 1 && b_in.size(0) == oc),
            "conv_transpose2d: bias {} does not match {} output channels", b_in.str(), oc);
  Tensor x = x_in.contiguous(), w = w_in.contiguous(), b = contiguous_or_undefined(b_in);
  int64_t oh = (x.size(2) - 1) * p.stride_h - p.pad_top - p.pad_bottom +
               p.dilation_h * (w.size(2) - 1) + p.output_padding_h + 1;
  int64_t ow = (x.size(3) - 1) * p.stride_w - p.pad_left - p.pad_right +
               p.dilation_w * (w.size(3) - 1) + p.output_padding_w + 1;
  CVD_CHECK(oh > 0 && ow > 0, "conv_transpose2d: empty output for input {}", x.str());
  Tensor y = empty_like_kind({x.size(0), oc, oh, ow}, x);
  dispatch(OpId::conv_transpose2d, x, KernelArgs{{x, w, b}, {y}, &p});
  if (!any_requires_grad({x, w, b})) return y;
  return record(
      "conv_transpose2d", y, {x, w, b},
      [xsaved = SavedTensor(x), xshape = x.shape(), ws = w.detach(), has_b = b.defined(), oc, p](
          const Tensor& g_in, const std::vector<bool>& need) {
        Tensor g = g_in.contiguous();
        Tensor gx, gw, gb;
        if (need[0]) {
          gx = empty_like_kind(xshape, ws);
          dispatch(OpId::conv_transpose2d_backward_data, g, KernelArgs{{g, ws}, {gx}, &p});
        }
        if (need[1] || (has_b && need[2])) {
          const Tensor xs = xsaved.get();
          gw = empty_like_kind(ws.shape(), ws);
          if (has_b && need[2]) gb = empty_like_kind({oc}, ws);
          dispatch(OpId::conv_transpose2d_backward_weight, g, KernelArgs{{g, xs}, {gw, gb}, &p});
          if (!need[1]) gw = Tensor();
        }
        return std::vector<Tensor>{gx, gw, gb};
      });
}

// ---- batch_norm ------------------------------------------------------------------------------
namespace {

// The checked, contiguous operands of a batch norm and its forward result.
struct BatchNormForward {
  Tensor x, gamma, beta, y, mean, invstd;
};

BatchNormForward batch_norm_forward(const char* op, const Tensor& x_in, const Tensor& running_mean,
                                    const Tensor& running_var, const Tensor& gamma_in,
                                    const Tensor& beta_in, const BatchNormParams& p) {
  CVD_CHECK(x_in.dim() == 4, "{}: x {} must be 4-d NCHW", op, x_in.str());
  int64_t c = x_in.size(1);
  for (const Tensor* t : {&running_mean, &running_var, &gamma_in, &beta_in}) {
    if (!t->defined()) continue;
    check_same_kind(op, x_in, *t);
    CVD_CHECK(t->dim() == 1 && t->size(0) == c, "{}: {} does not match {} channels", op, t->str(),
              c);
  }
  CVD_CHECK(running_mean.defined() && running_var.defined(), "{}: running statistics are required",
            op);
  CVD_CHECK(running_mean.is_contiguous() && running_var.is_contiguous(),
            "{}: running statistics must be contiguous", op);
  CVD_CHECK(!p.training || x_in.numel() / c > 1,
            "{}: training needs more than one value per channel, got {}", op, x_in.str());
  BatchNormForward f;
  f.x = x_in.contiguous();
  f.gamma = contiguous_or_undefined(gamma_in);
  f.beta = contiguous_or_undefined(beta_in);
  f.y = empty_like_kind(f.x.shape(), f.x);
  f.mean = empty_like_kind({c}, f.x);
  f.invstd = empty_like_kind({c}, f.x);
  dispatch(OpId::batch_norm, f.x,
           KernelArgs{{f.x, f.gamma, f.beta, running_mean.detach(), running_var.detach()},
                      {f.y, f.mean, f.invstd},
                      &p});
  if (p.training) {
    running_mean.bump_version();
    running_var.bump_version();
  }
  return f;
}

// d(loss)/d(x, gamma, beta) of a batch norm from d(loss)/d(y), y = act(bn(x)) with a fused
// activation (whose mask needs beta, bs).
std::vector<Tensor> batch_norm_grads(const Tensor& g, const Tensor& xs, const Tensor& gs,
                                     const Tensor& bs, const Tensor& mean, const Tensor& invstd,
                                     const BatchNormParams& p, const std::vector<bool>& need) {
  int64_t c = xs.size(1);
  Tensor gx = need[0] ? empty_like_kind(xs.shape(), xs) : Tensor();
  Tensor gg = gs.defined() && need[1] ? empty_like_kind({c}, xs) : Tensor();
  Tensor gb = bs.defined() && need[2] ? empty_like_kind({c}, xs) : Tensor();
  KernelArgs a{{g, xs, gs, mean, invstd}, {gx, gg, gb}, &p};
  if (p.fused_act) a.in.push_back(bs);
  dispatch(OpId::batch_norm_backward, g, a);
  return {gx, gg, gb};
}

// act((x - mean) * invstd * gamma + beta) with given statistics and the eps and fused activation
// of `fused` (the eval-mode kernel, to which the statistics are passed as running mean and
// var = 1 / invstd^2 - eps).
Tensor batch_norm_apply(const Tensor& xs, const Tensor& gs, const Tensor& bs, const Tensor& mean,
                        const Tensor& var, const BatchNormParams& fused) {
  BatchNormParams p = fused;
  p.training = false;
  p.momentum = 0.0;
  Tensor y = empty_like_kind(xs.shape(), xs);
  Tensor m = empty_like_kind(mean.shape(), mean), s = empty_like_kind(mean.shape(), mean);
  dispatch(OpId::batch_norm, xs, KernelArgs{{xs, gs, bs, mean, var}, {y, m, s}, &p});
  return y;
}

}  // namespace

Tensor batch_norm(const Tensor& x_in, const Tensor& running_mean, const Tensor& running_var,
                  const Tensor& gamma_in, const Tensor& beta_in, const BatchNormParams& p) {
  BatchNormForward f =
      batch_norm_forward("batch_norm", x_in, running_mean, running_var, gamma_in, beta_in, p);
  if (!any_requires_grad({f.x, f.gamma, f.beta})) return f.y;
  return record("batch_norm", f.y, {f.x, f.gamma, f.beta},
                [xs = f.x.detach(), gs = f.gamma.defined() ? f.gamma.detach() : Tensor(),
                 bs = f.beta.defined() ? f.beta.detach() : Tensor(), mean = f.mean,
                 invstd = f.invstd, p](const Tensor& g_in, const std::vector<bool>& need) {
                  return batch_norm_grads(g_in.contiguous(), xs, gs, bs, mean, invstd, p, need);
                });
}

Tensor batch_norm_act(const Tensor& x_in, const Tensor& running_mean, const Tensor& running_var,
                      const Tensor& gamma_in, const Tensor& beta_in, const BatchNormParams& p_in,
                      const UnaryParams& act) {
  CVD_CHECK(act.op == UnaryOp::relu || act.op == UnaryOp::clip,
            "batch_norm_act: the activation must be relu or clip (relu6)");
  // One kernel call each way: the forward writes act(y), the backward masks gy itself.
  BatchNormParams p = p_in;
  p.fused_act = true;
  p.act = act;
  BatchNormForward f =
      batch_norm_forward("batch_norm_act", x_in, running_mean, running_var, gamma_in, beta_in, p);
  Tensor z = f.y;
  if (!any_requires_grad({f.x, f.gamma, f.beta})) return z;
  // Keeps x (as batch_norm does), not z: backward recomputes the pre-activation from x for the
  // activation's mask, so z lives only as long as its consumers keep it.
  Tensor var;
  {
    NoGradGuard no_grad;
    var = add_scalar(reciprocal(mul(f.invstd, f.invstd)), -p.eps);
  }
  const Tensor xs = f.x.detach(), gs = f.gamma.defined() ? f.gamma.detach() : Tensor(),
               bs = f.beta.defined() ? f.beta.detach() : Tensor();
  record("batch_norm_act", z, {f.x, f.gamma, f.beta},
         [xs, gs, bs, mean = f.mean, invstd = f.invstd, p](const Tensor& g_in,
                                                           const std::vector<bool>& need) {
           return batch_norm_grads(g_in.contiguous(), xs, gs, bs, mean, invstd, p, need);
         });
  // Its consumers (convolutions) may recompute z instead of keeping it.
  mark_rematerializable(z, [xs, gs, bs, mean = f.mean, var, p] {
    return batch_norm_apply(xs, gs, bs, mean, var, p);
  });
  return z;
}

// ---- pooling ---------------------------------------------------------------------------------
static Shape pool_shape(const Tensor& x, const Pool2dParams& p, const char* op) {
  CVD_CHECK(x.dim() == 4, "{}: x {} must be 4-d", op, x.str());
  CVD_CHECK(p.kernel_h >= 1 && p.kernel_w >= 1 && p.stride_h >= 1 && p.stride_w >= 1,
            "{}: kernel and stride must be >= 1", op);
  CVD_CHECK(p.pad_top <= p.kernel_h / 2 && p.pad_left <= p.kernel_w / 2 &&
                p.pad_bottom <= p.kernel_h / 2 && p.pad_right <= p.kernel_w / 2,
            "{}: padding must be at most half the kernel", op);
  int64_t oh =
      pool_out_size(x.size(2), p.kernel_h, p.stride_h, p.pad_top, p.pad_bottom, p.ceil_mode);
  int64_t ow =
      pool_out_size(x.size(3), p.kernel_w, p.stride_w, p.pad_left, p.pad_right, p.ceil_mode);
  CVD_CHECK(oh > 0 && ow > 0, "{}: input {} too small", op, x.str());
  return {x.size(0), x.size(1), oh, ow};
}

Tensor max_pool2d(const Tensor& x_in, const Pool2dParams& p) {
  Tensor x = x_in.contiguous();
  Tensor y = empty_like_kind(pool_shape(x, p, "max_pool2d"), x);
  dispatch(OpId::max_pool2d, x, KernelArgs{{x}, {y}, &p});
  if (!any_requires_grad({x})) return y;
  return record("max_pool2d", y, {x},
                [xsaved = SavedTensor(x), p](const Tensor& g_in, const std::vector<bool>&) {
                  Tensor g = g_in.contiguous();
                  const Tensor xs = xsaved.get();
                  Tensor gx = empty_like_kind(xs.shape(), xs);
                  dispatch(OpId::max_pool2d_backward, g, KernelArgs{{g, xs}, {gx}, &p});
                  return std::vector<Tensor>{gx};
                });
}

Tensor avg_pool2d(const Tensor& x_in, const Pool2dParams& p) {
  Tensor x = x_in.contiguous();
  Tensor y = empty_like_kind(pool_shape(x, p, "avg_pool2d"), x);
  dispatch(OpId::avg_pool2d, x, KernelArgs{{x}, {y}, &p});
  if (!any_requires_grad({x})) return y;
  return record("avg_pool2d", y, {x},
                [xshape = x.shape(), p](const Tensor& g_in, const std::vector<bool>&) {
                  Tensor g = g_in.contiguous();
                  Tensor gx = empty_like_kind(xshape, g);
                  dispatch(OpId::avg_pool2d_backward, g, KernelArgs{{g}, {gx}, &p});
                  return std::vector<Tensor>{gx};
                });
}

// ---- resizing --------------------------------------------------------------------------------
static Tensor upsample(const Tensor& x_in, int64_t oh, int64_t ow, const UpsampleParams& p,
                       OpId fwd, OpId bwd, const char* name) {
  CVD_CHECK(x_in.dim() == 4, "{}: x {} must be 4-d", name, x_in.str());
  CVD_CHECK(oh > 0 && ow > 0, "{}: output size {}x{} must be positive", name, oh, ow);
  Tensor x = x_in.contiguous();
  Tensor y = empty_like_kind({x.size(0), x.size(1), oh, ow}, x);
  dispatch(fwd, x, KernelArgs{{x}, {y}, &p});
  if (!any_requires_grad({x})) return y;
  return record(name, y, {x},
                [xshape = x.shape(), p, bwd](const Tensor& g_in, const std::vector<bool>&) {
                  Tensor g = g_in.contiguous();
                  Tensor gx = empty_like_kind(xshape, g);
                  dispatch(bwd, g, KernelArgs{{g}, {gx}, &p});
                  return std::vector<Tensor>{gx};
                });
}

Tensor upsample_bilinear2d(const Tensor& x, int64_t oh, int64_t ow, bool align_corners) {
  return upsample(x, oh, ow, UpsampleParams{align_corners}, OpId::upsample_bilinear2d,
                  OpId::upsample_bilinear2d_backward, "upsample_bilinear2d");
}

Tensor upsample_nearest2d(const Tensor& x, int64_t oh, int64_t ow) {
  return upsample(x, oh, ow, UpsampleParams{}, OpId::upsample_nearest2d,
                  OpId::upsample_nearest2d_backward, "upsample_nearest2d");
}

Tensor upsample_bicubic2d(const Tensor& x, int64_t oh, int64_t ow, bool align_corners,
                          double scale_h, double scale_w) {
  CVD_CHECK(scale_h >= 0 && scale_w >= 0 && std::isfinite(scale_h) && std::isfinite(scale_w),
            "upsample_bicubic2d: scale factors must be finite and >= 0, got {}, {}", scale_h,
            scale_w);
  return upsample(x, oh, ow, UpsampleParams{align_corners, scale_h, scale_w},
                  OpId::upsample_bicubic2d, OpId::upsample_bicubic2d_backward,
                  "upsample_bicubic2d");
}

// ---- matmul / linear -------------------------------------------------------------------------
// c[B,M,N] = op(a) op(b) on 3-d contiguous operands.
static Tensor matmul3(const Tensor& a, const Tensor& b, bool ta, bool tb) {
  int64_t B = a.size(0), M = ta ? a.size(2) : a.size(1), N = tb ? b.size(1) : b.size(2);
  Tensor c = empty_like_kind({B, M, N}, a);
  MatmulParams p{ta, tb};
  dispatch(OpId::matmul, a, KernelArgs{{a, b}, {c}, &p});
  return c;
}

// Broadcast batch dims: both operands expanded to the common batch shape and flattened to 3-d
// (expand's backward sums the gradient back over the broadcast dims).
static Tensor matmul_broadcast(const Tensor& a_in, const Tensor& b_in) {
  Shape ab(a_in.shape().begin(), a_in.shape().end() - 2);
  Shape bb(b_in.shape().begin(), b_in.shape().end() - 2);
  Shape batch = broadcast_shapes(ab, bb);
  int64_t count = 1;
  for (int64_t d : batch) count *= d;
  const int64_t M = a_in.size(-2), K = a_in.size(-1), N = b_in.size(-1);
  auto flat = [&](const Tensor& t, int64_t rows, int64_t cols) {
    Shape full = batch;
    full.push_back(rows);
    full.push_back(cols);
    return reshape(expand(t, full), {count, rows, cols});
  };
  Tensor c = matmul(flat(a_in, M, K), flat(b_in, K, N));
  Shape out = batch;
  out.push_back(M);
  out.push_back(N);
  return reshape(c, out);
}

Tensor matmul(const Tensor& a_in, const Tensor& b_in) {
  check_same_kind("matmul", a_in, b_in);
  CVD_CHECK(a_in.dim() >= 2 && b_in.dim() >= 2, "matmul: unsupported shapes {} x {}", a_in.str(),
            b_in.str());
  int64_t K = a_in.size(-1);
  CVD_CHECK(b_in.size(-2) == K, "matmul: inner sizes differ: {} x {}", a_in.str(), b_in.str());
  const bool same_3d = a_in.dim() == 3 && b_in.dim() == 3 && a_in.size(0) == b_in.size(0);
  if (b_in.dim() > 2 && !same_3d) return matmul_broadcast(a_in, b_in);
  Shape out = a_in.shape();
  out.back() = b_in.size(-1);
  Tensor a, b;
  if (b_in.dim() == 2) {
    // b shared by every row of a: one [1, rows, K] x [1, K, N] product.
    a = a_in.contiguous().reshape({1, a_in.numel() / K, K});
    b = b_in.contiguous().reshape({1, K, b_in.size(1)});
  } else {
    a = a_in.contiguous();
    b = b_in.contiguous();
  }
  Tensor c;
  {
    NoGradGuard ng;
    c = matmul3(a.detach(), b.detach(), false, false).reshape(out);
  }
  if (!any_requires_grad({a, b})) return c;
  Tensor c3 = c.reshape({a.size(0), a.size(1), b.size(2)});
  Tensor r =
      record("matmul", c3, {a, b},
             [as = a.detach(), bs = b.detach()](const Tensor& g_in, const std::vector<bool>& need) {
               Tensor g = g_in.contiguous();
               Tensor ga, gb;
               if (need[0]) ga = matmul3(g, bs, false, true);
               if (need[1]) gb = matmul3(as, g, true, false);
               return std::vector<Tensor>{ga, gb};
             });
  return r.reshape(out);
}

Tensor linear(const Tensor& x, const Tensor& w, const Tensor& b) {
  CVD_CHECK(w.dim() == 2 && x.size(-1) == w.size(1), "linear: x {} does not match weight {}",
            x.str(), w.str());
  Tensor y = matmul(x, transpose(w, 0, 1));
  return b.defined() ? add(y, b) : y;
}

// ---- grid_sample -----------------------------------------------------------------------------
Tensor grid_sample(const Tensor& x_in, const Tensor& grid_in, const GridSampleParams& p) {
  check_same_kind("grid_sample", x_in, grid_in);
  CVD_CHECK(x_in.dim() == 4 && grid_in.dim() == 4 && grid_in.size(3) == 2 &&
                grid_in.size(0) == x_in.size(0),
            "grid_sample: x {} and grid {} must be [N,C,H,W] and [N,Ho,Wo,2]", x_in.str(),
            grid_in.str());
  Tensor x = x_in.contiguous(), grid = grid_in.contiguous();
  Tensor y = empty_like_kind({x.size(0), x.size(1), grid.size(1), grid.size(2)}, x);
  dispatch(OpId::grid_sample, x, KernelArgs{{x, grid}, {y}, &p});
  if (!any_requires_grad({x, grid})) return y;
  return record(
      "grid_sample", y, {x, grid},
      [xs = x.detach(), gs = grid.detach(), p](const Tensor& g_in, const std::vector<bool>& need) {
        Tensor g = g_in.contiguous();
        Tensor gx = need[0] ? empty_like_kind(xs.shape(), xs) : Tensor();
        Tensor gg = need[1] ? empty_like_kind(gs.shape(), gs) : Tensor();
        dispatch(OpId::grid_sample_backward, g, KernelArgs{{g, xs, gs}, {gx, gg}, &p});
        return std::vector<Tensor>{gx, gg};
      });
}

}  // namespace cvd
