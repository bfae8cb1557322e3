// Reference kernels of batch normalisation and 2-D max / average pooling, forward and backward,
// PyTorch semantics.
#include <algorithm>
#include <cmath>
#include <limits>

#include "engine/kernel_params.h"
#include "kernels/reference/reference_access.h"
#include "kernels/reference/reference_kernels.h"

namespace cvd::reference {

namespace {

// x [N, C, spatial...] viewed as [N, C, inner].
struct ChannelLayout {
  int64_t n, c, inner;
  int64_t index(int64_t ni, int64_t ci, int64_t i) const { return (ni * c + ci) * inner + i; }
  int64_t count() const { return n * inner; }  // elements per channel
};

ChannelLayout channel_layout(const Tensor& x) {
  CVD_ASSERT(x.dim() >= 2);
  return {x.shape()[0], x.shape()[1], dims_product(x.shape(), 2, x.dim())};
}

// A defined tensor must be an f64 contiguous vector of `c` elements.
bool is_channel_vector(const Tensor& t, int64_t c) {
  return is_f64_contiguous(t) && t.dim() == 1 && t.shape()[0] == c;
}

}  // namespace

// in {x [N,C,...], gamma?, beta?, running_mean [C], running_var [C]},
// out {y, mean [C], invstd [C]}; BatchNormParams. Training also updates the running stats.
void batch_norm(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 5 && a.out.size() == 3 && a.params != nullptr);
  const Tensor& x = a.in[0];
  const Tensor& gamma = a.in[1];
  const Tensor& beta = a.in[2];
  const Tensor& running_mean = a.in[3];
  const Tensor& running_var = a.in[4];
  const Tensor& y = a.out[0];
  const Tensor& mean = a.out[1];
  const Tensor& invstd = a.out[2];
  const BatchNormParams& p = a.p<BatchNormParams>();
  CVD_ASSERT(is_f64_contiguous(x) && is_f64_contiguous(y) && x.shape() == y.shape());
  const ChannelLayout l = channel_layout(x);
  CVD_ASSERT(!gamma.defined() || is_channel_vector(gamma, l.c));
  CVD_ASSERT(!beta.defined() || is_channel_vector(beta, l.c));
  CVD_ASSERT(is_channel_vector(running_mean, l.c) && is_channel_vector(running_var, l.c));
  CVD_ASSERT(is_channel_vector(mean, l.c) && is_channel_vector(invstd, l.c));
  CVD_ASSERT(!p.training || l.count() > 1);  // the unbiased variance needs two values

  const double* xp = x.data<double>();
  double* yp = y.data<double>();
  double* rm = running_mean.data<double>();
  double* rv = running_var.data<double>();
  for (int64_t c = 0; c < l.c; ++c) {
    double mu, var;
    if (p.training) {
      double sum = 0.0;
      for (int64_t n = 0; n < l.n; ++n) {
        for (int64_t i = 0; i < l.inner; ++i) sum += xp[l.index(n, c, i)];
      }
      mu = sum / static_cast<double>(l.count());
      double sq = 0.0;
      for (int64_t n = 0; n < l.n; ++n) {
        for (int64_t i = 0; i < l.inner; ++i) {
          const double d = xp[l.index(n, c, i)] - mu;
          sq += d * d;
        }
      }
      var = sq / static_cast<double>(l.count());
      const double unbiased = sq / static_cast<double>(l.count() - 1);
      rm[c] = (1.0 - p.momentum) * rm[c] + p.momentum * mu;
      rv[c] = (1.0 - p.momentum) * rv[c] + p.momentum * unbiased;
    } else {
      mu = rm[c];
      var = rv[c];
    }
    const double istd = 1.0 / std::sqrt(var + p.eps);
    mean.data<double>()[c] = mu;
    invstd.data<double>()[c] = istd;
    const double scale = gamma.defined() ? gamma.data<double>()[c] : 1.0;
    const double shift = beta.defined() ? beta.data<double>()[c] : 0.0;
    for (int64_t n = 0; n < l.n; ++n) {
      for (int64_t i = 0; i < l.inner; ++i) {
        const int64_t k = l.index(n, c, i);
        const double pre = (xp[k] - mu) * istd * scale + shift;
        yp[k] = p.fused_act ? unary_forward(p.act.op, pre, p.act.a, p.act.b) : pre;
      }
    }
  }
}

namespace {

// gy taken back through the fused activation: act'(gamma * (x - mean) * invstd + beta) * gy.
Tensor activation_gradient(const Tensor& gy, const Tensor& x, const Tensor& gamma,
                           const Tensor& beta, const Tensor& mean, const Tensor& invstd,
                           const BatchNormParams& p, const ChannelLayout& l) {
  CVD_ASSERT(!beta.defined() || is_channel_vector(beta, l.c));
  Tensor out = Tensor::empty(gy.shape(), DType::f64);
  const double *gyp = gy.data<double>(), *xp = x.data<double>();
  double* op = out.data<double>();
  for (int64_t c = 0; c < l.c; ++c) {
    const double mu = mean.data<double>()[c], istd = invstd.data<double>()[c];
    const double scale = gamma.defined() ? gamma.data<double>()[c] : 1.0;
    const double shift = beta.defined() ? beta.data<double>()[c] : 0.0;
    for (int64_t n = 0; n < l.n; ++n) {
      for (int64_t i = 0; i < l.inner; ++i) {
        const int64_t k = l.index(n, c, i);
        const double pre = (xp[k] - mu) * istd * scale + shift;
        const double y = unary_forward(p.act.op, pre, p.act.a, p.act.b);
        op[k] = unary_backward(p.act.op, gyp[k], pre, y, p.act.a, p.act.b);
      }
    }
  }
  return out;
}

}  // namespace

// in {gy, x, gamma?, mean [C], invstd [C][, beta? with fused_act]}, out {gx?, ggamma?, gbeta?};
// BatchNormParams. A fused activation first takes gy through act at the pre-activation
// gamma * xhat + beta; then, with xhat = (x - mean) * invstd:  gbeta = sum gy,
// ggamma = sum gy * xhat,
// training: gx = gamma * invstd * (gy - gbeta / m - xhat * ggamma / m)  (m values per channel;
//           the gradient flows through the batch statistics),
// eval:     gx = gamma * invstd * gy  (the statistics are constants).
void batch_norm_backward(const KernelArgs& a) {
  CVD_ASSERT(a.params != nullptr && a.out.size() == 3);
  const BatchNormParams& p = a.p<BatchNormParams>();
  CVD_ASSERT(a.in.size() == (p.fused_act ? 6u : 5u));
  const Tensor& gy_in = a.in[0];
  const Tensor& x = a.in[1];
  const Tensor& gamma = a.in[2];
  const Tensor& mean = a.in[3];
  const Tensor& invstd = a.in[4];
  const Tensor& gx = a.out[0];
  const Tensor& ggamma = a.out[1];
  const Tensor& gbeta = a.out[2];
  CVD_ASSERT(is_f64_contiguous(gy_in) && is_f64_contiguous(x) && gy_in.shape() == x.shape());
  const ChannelLayout l = channel_layout(x);
  CVD_ASSERT(!gamma.defined() || is_channel_vector(gamma, l.c));
  CVD_ASSERT(is_channel_vector(mean, l.c) && is_channel_vector(invstd, l.c));
  const Tensor gy =
      p.fused_act ? activation_gradient(gy_in, x, gamma, a.in[5], mean, invstd, p, l) : gy_in;
  CVD_ASSERT(!gx.defined() || (is_f64_contiguous(gx) && gx.shape() == x.shape()));
  CVD_ASSERT(!ggamma.defined() || is_channel_vector(ggamma, l.c));
  CVD_ASSERT(!gbeta.defined() || is_channel_vector(gbeta, l.c));

  const double* gyp = gy.data<double>();
  const double* xp = x.data<double>();
  for (int64_t c = 0; c < l.c; ++c) {
    const double mu = mean.data<double>()[c];
    const double istd = invstd.data<double>()[c];
    const double scale = gamma.defined() ? gamma.data<double>()[c] : 1.0;
    double sum_gy = 0.0, sum_gy_xhat = 0.0;
    for (int64_t n = 0; n < l.n; ++n) {
      for (int64_t i = 0; i < l.inner; ++i) {
        const int64_t k = l.index(n, c, i);
        sum_gy += gyp[k];
        sum_gy_xhat += gyp[k] * (xp[k] - mu) * istd;
      }
    }
    if (gbeta.defined()) gbeta.data<double>()[c] = sum_gy;
    if (ggamma.defined()) ggamma.data<double>()[c] = sum_gy_xhat;
    if (!gx.defined()) continue;
    double* gxp = gx.data<double>();
    const double m = static_cast<double>(l.count());
    for (int64_t n = 0; n < l.n; ++n) {
      for (int64_t i = 0; i < l.inner; ++i) {
        const int64_t k = l.index(n, c, i);
        const double xhat = (xp[k] - mu) * istd;
        gxp[k] = p.training ? scale * istd * (gyp[k] - sum_gy / m - xhat * sum_gy_xhat / m)
                            : scale * istd * gyp[k];
      }
    }
  }
}

namespace {

// x [N, C, H, W] pooled to y [N, C, OH, OW]; the output size comes from y.
struct PoolGeometry {
  int64_t planes, h, w, oh, ow;
};

PoolGeometry pool_geometry(const Tensor& x, const Tensor& y, const Pool2dParams& p) {
  CVD_ASSERT(is_f64_contiguous(x) && is_f64_contiguous(y) && x.dim() == 4 && y.dim() == 4);
  CVD_ASSERT(x.shape()[0] == y.shape()[0] && x.shape()[1] == y.shape()[1]);
  CVD_ASSERT(p.kernel_h >= 1 && p.kernel_w >= 1 && p.stride_h >= 1 && p.stride_w >= 1);
  CVD_ASSERT(p.pad_top >= 0 && p.pad_bottom >= 0 && p.pad_left >= 0 && p.pad_right >= 0);
  return {x.shape()[0] * x.shape()[1], x.shape()[2], x.shape()[3], y.shape()[2], y.shape()[3]};
}

// Index (into one H*W plane) of the max of the window of output (oh, ow), scanning rows then
// columns and keeping the first of equal values (a NaN wins, the last one, as PyTorch); -1 when
// the window holds no input pixel. Padding never wins.
int64_t window_argmax(const double* plane, const PoolGeometry& g, const Pool2dParams& p, int64_t oh,
                      int64_t ow) {
  int64_t best = -1;
  double best_value = -std::numeric_limits<double>::infinity();
  for (int64_t kh = 0; kh < p.kernel_h; ++kh) {
    const int64_t ih = oh * p.stride_h - p.pad_top + kh;
    if (ih < 0 || ih >= g.h) continue;
    for (int64_t kw = 0; kw < p.kernel_w; ++kw) {
      const int64_t iw = ow * p.stride_w - p.pad_left + kw;
      if (iw < 0 || iw >= g.w) continue;
      const double v = plane[ih * g.w + iw];
      if (best < 0 || v > best_value || std::isnan(v)) {
        best = ih * g.w + iw;
        best_value = v;
      }
    }
  }
  return best;
}

// Input rows [begin, end) of an average-pooling window and its divisor (PyTorch avg_pool2d).
struct AvgWindow {
  int64_t h0, h1, w0, w1;
  double divisor;
};

AvgWindow avg_window(const PoolGeometry& g, const Pool2dParams& p, int64_t oh, int64_t ow) {
  int64_t h0 = oh * p.stride_h - p.pad_top;
  int64_t w0 = ow * p.stride_w - p.pad_left;
  int64_t h1 = std::min<int64_t>(h0 + p.kernel_h, g.h + p.pad_bottom);
  int64_t w1 = std::min<int64_t>(w0 + p.kernel_w, g.w + p.pad_right);
  const int64_t padded_count = (h1 - h0) * (w1 - w0);
  h0 = std::max<int64_t>(h0, 0);
  w0 = std::max<int64_t>(w0, 0);
  h1 = std::min<int64_t>(h1, g.h);
  w1 = std::min<int64_t>(w1, g.w);
  const int64_t count = std::max<int64_t>(h1 - h0, 0) * std::max<int64_t>(w1 - w0, 0);
  return {h0, h1, w0, w1, static_cast<double>(p.count_include_pad ? padded_count : count)};
}

}  // namespace

// in {x [N,C,H,W]}, out {y [N,C,OH,OW]}; Pool2dParams.
void max_pool2d(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1 && a.params != nullptr);
  const Tensor& x = a.in[0];
  const Tensor& y = a.out[0];
  const Pool2dParams& p = a.p<Pool2dParams>();
  const PoolGeometry g = pool_geometry(x, y, p);
  for (int64_t pl = 0; pl < g.planes; ++pl) {
    const double* xp = x.data<double>() + pl * g.h * g.w;
    double* yp = y.data<double>() + pl * g.oh * g.ow;
    for (int64_t oh = 0; oh < g.oh; ++oh) {
      for (int64_t ow = 0; ow < g.ow; ++ow) {
        const int64_t best = window_argmax(xp, g, p, oh, ow);
        yp[oh * g.ow + ow] = best >= 0 ? xp[best] : -std::numeric_limits<double>::infinity();
      }
    }
  }
}

// in {gy [N,C,OH,OW], x [N,C,H,W]}, out {gx [N,C,H,W]}: gy goes to each window's argmax.
void max_pool2d_backward(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 2 && a.out.size() == 1 && a.params != nullptr);
  const Tensor& gy = a.in[0];
  const Tensor& x = a.in[1];
  const Tensor& gx = a.out[0];
  const Pool2dParams& p = a.p<Pool2dParams>();
  const PoolGeometry g = pool_geometry(x, gy, p);
  CVD_ASSERT(is_f64_contiguous(gx) && gx.shape() == x.shape());
  for (int64_t pl = 0; pl < g.planes; ++pl) {
    const double* xp = x.data<double>() + pl * g.h * g.w;
    const double* gyp = gy.data<double>() + pl * g.oh * g.ow;
    double* gxp = gx.data<double>() + pl * g.h * g.w;
    for (int64_t i = 0; i < g.h * g.w; ++i) gxp[i] = 0.0;
    for (int64_t oh = 0; oh < g.oh; ++oh) {
      for (int64_t ow = 0; ow < g.ow; ++ow) {
        const int64_t best = window_argmax(xp, g, p, oh, ow);
        if (best >= 0) gxp[best] += gyp[oh * g.ow + ow];
      }
    }
  }
}

// in {x [N,C,H,W]}, out {y [N,C,OH,OW]}; Pool2dParams (count_include_pad, ceil_mode via sizes).
void avg_pool2d(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1 && a.params != nullptr);
  const Tensor& x = a.in[0];
  const Tensor& y = a.out[0];
  const Pool2dParams& p = a.p<Pool2dParams>();
  const PoolGeometry g = pool_geometry(x, y, p);
  for (int64_t pl = 0; pl < g.planes; ++pl) {
    const double* xp = x.data<double>() + pl * g.h * g.w;
    double* yp = y.data<double>() + pl * g.oh * g.ow;
    for (int64_t oh = 0; oh < g.oh; ++oh) {
      for (int64_t ow = 0; ow < g.ow; ++ow) {
        const AvgWindow win = avg_window(g, p, oh, ow);
        double sum = 0.0;
        for (int64_t ih = win.h0; ih < win.h1; ++ih) {
          for (int64_t iw = win.w0; iw < win.w1; ++iw) sum += xp[ih * g.w + iw];
        }
        yp[oh * g.ow + ow] = win.divisor > 0 ? sum / win.divisor : 0.0;
      }
    }
  }
}

// in {gy [N,C,OH,OW]}, out {gx [N,C,H,W]}: each window spreads gy / divisor over its pixels.
void avg_pool2d_backward(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1 && a.params != nullptr);
  const Tensor& gy = a.in[0];
  const Tensor& gx = a.out[0];
  const Pool2dParams& p = a.p<Pool2dParams>();
  const PoolGeometry g = pool_geometry(gx, gy, p);
  for (int64_t pl = 0; pl < g.planes; ++pl) {
    const double* gyp = gy.data<double>() + pl * g.oh * g.ow;
    double* gxp = gx.data<double>() + pl * g.h * g.w;
    for (int64_t i = 0; i < g.h * g.w; ++i) gxp[i] = 0.0;
    for (int64_t oh = 0; oh < g.oh; ++oh) {
      for (int64_t ow = 0; ow < g.ow; ++ow) {
        const AvgWindow win = avg_window(g, p, oh, ow);
        if (win.divisor <= 0) continue;
        const double share = gyp[oh * g.ow + ow] / win.divisor;
        for (int64_t ih = win.h0; ih < win.h1; ++ih) {
          for (int64_t iw = win.w0; iw < win.w1; ++iw) gxp[ih * g.w + iw] += share;
        }
      }
    }
  }
}

}  // namespace cvd::reference
