// CUDA kernel bodies and op drivers of batch normalisation (train / eval, forward / backward) and
// 2-D max / average pooling (forward / backward), PyTorch semantics as the reference kernels.
// Per-channel sums run C * chunks threads (partial sums in double, then one thread per channel
// adds its chunks); backward pooling
// is a gather (one thread per input pixel visits the windows that contain it), so no kernel here
// needs atomics or shared memory. A block-level tree for the statistics is future work.
#pragma once
#include <cmath>

#include "engine/dispatch.h"
#include "engine/kernel_params.h"
#include "kernels/cuda/launch_body.h"

namespace cvd::cuda {

// x [N, C, inner...] as [N, C, inner].
struct ChannelGeometry {
  int64_t n, c, inner;
  CVD_HOST_DEVICE int64_t index(int64_t ni, int64_t ci, int64_t i) const {
    return (ni * c + ci) * inner + i;
  }
};

inline ChannelGeometry channel_geometry(const Tensor& x) {
  int64_t inner = 1;
  for (int d = 2; d < x.dim(); ++d) inner *= x.shape()[d];
  return {x.shape()[0], x.shape()[1], inner};
}

// gy taken back through a fused activation (BatchNormParams::fused_act): gy where act passes it
// at the pre-activation (x - mean) * invstd * gamma + beta; gy itself when off.
template <class T>
struct ActGate {
  const T *gamma, *beta, *mean, *invstd;  // gamma, beta may be nullptr
  bool on;
  UnaryOp op;
  T a, b;
  CVD_HOST_DEVICE T operator()(T gy, T x, int64_t c) const {
    if (!on) return gy;
    const T pre = (x - mean[c]) * invstd[c] * (gamma ? gamma[c] : T(1)) + (beta ? beta[c] : T(0));
    return unary_backward(op, gy, pre, unary_forward(op, pre, a, b), a, b);
  }
};

template <class T>
ActGate<T> act_gate(const KernelArgs& a) {
  const BatchNormParams& p = a.p<BatchNormParams>();
  const bool on = p.fused_act;
  return {data_or_null<T>(a.in[2]),
          on ? data_or_null<T>(a.in[5]) : nullptr,
          a.in[3].data<T>(),
          a.in[4].data<T>(),
          on,
          p.act.op,
          static_cast<T>(p.act.a),
          static_cast<T>(p.act.b)};
}

// Per-channel sums in chunks, so that C * chunks threads share the work: thread t = (c, chunk)
// writes partial[2 t] = sum a, partial[2 t + 1] = sum b over its elements of channel c, in double.
// Forward (gy == nullptr): a = x - s, b = (x - s)^2 with s = the channel's first element (a shift
// that keeps E[b] - E[a]^2 accurate); backward: a = gy, b = gy * (x - mean) * invstd, gy through
// the gate of a fused activation.
template <class T>
struct ChannelPartialSumsBody {
  const T *x, *gy, *mean, *invstd;
  double* partial;
  ChannelGeometry g;
  int64_t chunk, chunks;
  ActGate<T> gate;
  CVD_HOST_DEVICE void operator()(int64_t t) const {
    const int64_t c = t / chunks, k = t % chunks;
    const int64_t count = g.n * g.inner;
    const int64_t end = (k + 1) * chunk < count ? (k + 1) * chunk : count;
    const double shift = gy ? 0.0 : static_cast<double>(x[g.index(0, c, 0)]);
    double sa = 0.0, sb = 0.0;
    for (int64_t e = k * chunk; e < end; ++e) {
      const int64_t idx = g.index(e / g.inner, c, e % g.inner);
      if (gy) {
        const T gm = gate(gy[idx], x[idx], c);
        sa += gm;
        sb += static_cast<double>(gm) * (static_cast<double>(x[idx]) - mean[c]) * invstd[c];
      } else {
        const double d = static_cast<double>(x[idx]) - shift;
        sa += d;
        sb += d * d;
      }
    }
    partial[2 * t] = sa;
    partial[2 * t + 1] = sb;
  }
};

// One thread per channel: mean / invstd (training: batch statistics from the partial sums, and
// the running-stat update; eval: from the running statistics).
template <class T>
struct BatchNormStatsBody {
  const T* x;
  const double* partial;  // training only
  T *running_mean, *running_var, *mean, *invstd;
  ChannelGeometry g;
  int64_t chunks;
  bool training;
  double momentum, eps;
  CVD_HOST_DEVICE void operator()(int64_t c) const {
    double mu, var;
    if (training) {
      const double count = static_cast<double>(g.n * g.inner);
      double sa = 0.0, sb = 0.0;
      for (int64_t k = 0; k < chunks; ++k) {
        sa += partial[2 * (c * chunks + k)];
        sb += partial[2 * (c * chunks + k) + 1];
      }
      const double shifted_mean = sa / count;
      mu = static_cast<double>(x[g.index(0, c, 0)]) + shifted_mean;
      double sq = sb - sa * shifted_mean;  // sum of squared deviations
      sq = sq < 0.0 ? 0.0 : sq;
      var = sq / count;
      const double unbiased = sq / (count - 1.0);
      running_mean[c] = static_cast<T>((1.0 - momentum) * running_mean[c] + momentum * mu);
      running_var[c] = static_cast<T>((1.0 - momentum) * running_var[c] + momentum * unbiased);
    } else {
      mu = running_mean[c];
      var = running_var[c];
    }
    mean[c] = static_cast<T>(mu);
    invstd[c] = static_cast<T>(1.0 / sqrt(var + eps));
  }
};

template <class T>
struct BatchNormApplyBody {
  const T *x, *gamma, *beta, *mean, *invstd;  // gamma, beta may be nullptr
  T* y;
  ChannelGeometry g;
  bool fused_act;
  UnaryOp op;
  T a, b;
  CVD_HOST_DEVICE void operator()(int64_t k) const {
    const int64_t c = (k / g.inner) % g.c;
    const T scale = gamma ? gamma[c] : T(1);
    const T shift = beta ? beta[c] : T(0);
    const T pre = (x[k] - mean[c]) * invstd[c] * scale + shift;
    y[k] = fused_act ? unary_forward(op, pre, a, b) : pre;
  }
};

// One thread per channel: sums[c] = sum gy, sums[C + c] = sum gy * xhat, from the partial sums.
template <class T>
struct BatchNormBackwardSumsBody {
  const double* partial;
  T* sums;
  int64_t channels, chunks;
  CVD_HOST_DEVICE void operator()(int64_t c) const {
    double s = 0.0, sx = 0.0;
    for (int64_t k = 0; k < chunks; ++k) {
      s += partial[2 * (c * chunks + k)];
      sx += partial[2 * (c * chunks + k) + 1];
    }
    sums[c] = static_cast<T>(s);
    sums[channels + c] = static_cast<T>(sx);
  }
};

template <class T>
struct BatchNormBackwardDataBody {
  const T *gy, *x, *gamma, *mean, *invstd, *sums;
  T *gx, *ggamma, *gbeta;  // ggamma / gbeta written by the thread of element 0 of each channel
  ChannelGeometry g;
  bool training;
  ActGate<T> gate;
  CVD_HOST_DEVICE void operator()(int64_t k) const {
    const int64_t c = (k / g.inner) % g.c;
    const T sum_gy = sums[c], sum_gy_xhat = sums[g.c + c];
    if (k == c * g.inner) {  // first element of channel c (batch 0, position 0)
      if (gbeta) gbeta[c] = sum_gy;
      if (ggamma) ggamma[c] = sum_gy_xhat;
    }
    if (!gx) return;
    const T scale = gamma ? gamma[c] : T(1);
    const T m = static_cast<T>(g.n * g.inner);
    const T xhat = (x[k] - mean[c]) * invstd[c];
    const T gm = gate(gy[k], x[k], c);
    gx[k] = training ? scale * invstd[c] * (gm - sum_gy / m - xhat * sum_gy_xhat / m)
                     : scale * invstd[c] * gm;
  }
};

struct PoolGeometry {
  int64_t planes, h, w, oh, ow;
  int kernel_h, kernel_w, stride_h, stride_w, pad_top, pad_left, pad_bottom, pad_right;
  bool count_include_pad;
};

inline PoolGeometry pool_geometry(const Tensor& x, const Tensor& y, const Pool2dParams& p) {
  return {x.shape()[0] * x.shape()[1],
          x.shape()[2],
          x.shape()[3],
          y.shape()[2],
          y.shape()[3],
          p.kernel_h,
          p.kernel_w,
          p.stride_h,
          p.stride_w,
          p.pad_top,
          p.pad_left,
          p.pad_bottom,
          p.pad_right,
          p.count_include_pad};
}

// Index in the plane of the max of window (oh, ow): first of equal values, a NaN wins (the last
// one); -1 when the window holds no input pixel.
template <class T>
CVD_HOST_DEVICE int64_t window_argmax(const T* plane, const PoolGeometry& g, int64_t oh,
                                      int64_t ow) {
  int64_t best = -1;
  T best_value = T(0);
  for (int64_t kh = 0; kh < g.kernel_h; ++kh) {
    const int64_t ih = oh * g.stride_h - g.pad_top + kh;
    if (ih < 0 || ih >= g.h) continue;
    for (int64_t kw = 0; kw < g.kernel_w; ++kw) {
      const int64_t iw = ow * g.stride_w - g.pad_left + kw;
      if (iw < 0 || iw >= g.w) continue;
      const T v = plane[ih * g.w + iw];
      if (best < 0 || v > best_value || v != v) {
        best = ih * g.w + iw;
        best_value = v;
      }
    }
  }
  return best;
}

// Output windows [o0, o1) along one axis that contain input index i (before clipping to range).
struct WindowRange {
  int64_t o0, o1;
};
CVD_HOST_DEVICE WindowRange windows_containing(int64_t i, int64_t pad, int64_t kernel,
                                               int64_t stride, int64_t out) {
  // o * stride - pad <= i < o * stride - pad + kernel
  const int64_t hi = i + pad;  // o * stride <= hi
  int64_t o1 = hi / stride + 1;
  int64_t lo = hi - kernel + 1;  // o * stride >= lo
  int64_t o0 = lo <= 0 ? 0 : (lo + stride - 1) / stride;
  if (o1 > out) o1 = out;
  return {o0, o1};
}

template <class T>
struct MaxPoolBody {
  const T* x;
  T* y;
  PoolGeometry g;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    const int64_t ow = i % g.ow, oh = (i / g.ow) % g.oh, pl = i / (g.ow * g.oh);
    const T* plane = x + pl * g.h * g.w;
    const int64_t best = window_argmax(plane, g, oh, ow);
    y[i] = best >= 0 ? plane[best] : -static_cast<T>(INFINITY);
  }
};

template <class T>
struct MaxPoolBackwardBody {
  const T *gy, *x;
  T* gx;
  PoolGeometry g;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    const int64_t iw = i % g.w, ih = (i / g.w) % g.h, pl = i / (g.w * g.h);
    const T* plane = x + pl * g.h * g.w;
    const WindowRange rh = windows_containing(ih, g.pad_top, g.kernel_h, g.stride_h, g.oh);
    const WindowRange rw = windows_containing(iw, g.pad_left, g.kernel_w, g.stride_w, g.ow);
    T acc = T(0);
    for (int64_t oh = rh.o0; oh < rh.o1; ++oh)
      for (int64_t ow = rw.o0; ow < rw.o1; ++ow) {
        if (window_argmax(plane, g, oh, ow) == ih * g.w + iw)
          acc += gy[(pl * g.oh + oh) * g.ow + ow];
      }
    gx[i] = acc;
  }
};

// Input window [h0, h1) x [w0, w1) of an average-pooling output and its divisor (PyTorch).
struct AvgWindow {
  int64_t h0, h1, w0, w1;
  int64_t divisor;
};
CVD_HOST_DEVICE AvgWindow avg_window(const PoolGeometry& g, int64_t oh, int64_t ow) {
  int64_t h0 = oh * g.stride_h - g.pad_top, w0 = ow * g.stride_w - g.pad_left;
  int64_t h1 = h0 + g.kernel_h, w1 = w0 + g.kernel_w;
  if (h1 > g.h + g.pad_bottom) h1 = g.h + g.pad_bottom;
  if (w1 > g.w + g.pad_right) w1 = g.w + g.pad_right;
  const int64_t padded = (h1 - h0) * (w1 - w0);
  h0 = h0 < 0 ? 0 : h0;
  w0 = w0 < 0 ? 0 : w0;
  h1 = h1 > g.h ? g.h : h1;
  w1 = w1 > g.w ? g.w : w1;
  const int64_t count = (h1 > h0 ? h1 - h0 : 0) * (w1 > w0 ? w1 - w0 : 0);
  return {h0, h1, w0, w1, g.count_include_pad ? padded : count};
}

template <class T>
struct AvgPoolBody {
  const T* x;
  T* y;
  PoolGeometry g;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    const int64_t ow = i % g.ow, oh = (i / g.ow) % g.oh, pl = i / (g.ow * g.oh);
    const T* plane = x + pl * g.h * g.w;
    const AvgWindow win = avg_window(g, oh, ow);
    T sum = T(0);
    for (int64_t ih = win.h0; ih < win.h1; ++ih)
      for (int64_t iw = win.w0; iw < win.w1; ++iw) sum += plane[ih * g.w + iw];
    y[i] = win.divisor > 0 ? sum / static_cast<T>(win.divisor) : T(0);
  }
};

template <class T>
struct AvgPoolBackwardBody {
  const T* gy;
  T* gx;
  PoolGeometry g;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    const int64_t iw = i % g.w, ih = (i / g.w) % g.h, pl = i / (g.w * g.h);
    const WindowRange rh = windows_containing(ih, g.pad_top, g.kernel_h, g.stride_h, g.oh);
    const WindowRange rw = windows_containing(iw, g.pad_left, g.kernel_w, g.stride_w, g.ow);
    T acc = T(0);
    for (int64_t oh = rh.o0; oh < rh.o1; ++oh)
      for (int64_t ow = rw.o0; ow < rw.o1; ++ow) {
        const AvgWindow win = avg_window(g, oh, ow);
        if (win.divisor <= 0 || ih < win.h0 || ih >= win.h1 || iw < win.w0 || iw >= win.w1)
          continue;
        acc += gy[(pl * g.oh + oh) * g.ow + ow] / static_cast<T>(win.divisor);
      }
    gx[i] = acc;
  }
};

// ---- Op drivers ---------------------------------------------------------------------------------

// Elements per chunk of the per-channel sums and the number of chunks per channel.
inline int64_t channel_chunks(const ChannelGeometry& g, int64_t chunk) {
  const int64_t count = g.n * g.inner;
  return count == 0 ? 1 : (count + chunk - 1) / chunk;
}
inline constexpr int64_t kChannelChunk = 2048;

// in {x, gamma?, beta?, running_mean, running_var}, out {y, mean, invstd}.
template <class Launch>
void batch_norm_op(const KernelArgs& a) {
  const Tensor& x = a.in[0];
  const BatchNormParams& p = a.p<BatchNormParams>();
  const ChannelGeometry g = channel_geometry(x);
  const int64_t chunks = channel_chunks(g, kChannelChunk);
  Tensor partial;
  if (p.training) {
    partial = Tensor::empty({g.c * chunks * 2}, DType::f64, x.device());
    Launch::launch(g.c * chunks,
                   ChannelPartialSumsBody<float>{x.data<float>(), nullptr, nullptr, nullptr,
                                                 partial.data<double>(), g, kChannelChunk, chunks,
                                                 ActGate<float>{}});
  }
  Launch::launch(g.c, BatchNormStatsBody<float>{x.data<float>(), data_or_null<double>(partial),
                                                a.in[3].data<float>(), a.in[4].data<float>(),
                                                a.out[1].data<float>(), a.out[2].data<float>(), g,
                                                chunks, p.training, p.momentum, p.eps});
  Launch::launch(x.numel(),
                 BatchNormApplyBody<float>{x.data<float>(), data_or_null<float>(a.in[1]),
                                           data_or_null<float>(a.in[2]), a.out[1].data<float>(),
                                           a.out[2].data<float>(), a.out[0].data<float>(), g,
                                           p.fused_act, p.act.op, static_cast<float>(p.act.a),
                                           static_cast<float>(p.act.b)});
}

// in {gy, x, gamma?, mean, invstd[, beta? with fused_act]}, out {gx?, ggamma?, gbeta?}.
template <class Launch>
void batch_norm_backward_op(const KernelArgs& a) {
  const Tensor &gy = a.in[0], &x = a.in[1];
  const ChannelGeometry g = channel_geometry(x);
  const int64_t chunks = channel_chunks(g, kChannelChunk);
  const Tensor partial = Tensor::empty({g.c * chunks * 2}, DType::f64, x.device());
  const Tensor sums = Tensor::empty({2 * g.c}, DType::f32, x.device());
  auto out = [&](size_t k) { return k < a.out.size() ? data_or_null<float>(a.out[k]) : nullptr; };
  Launch::launch(g.c * chunks, ChannelPartialSumsBody<float>{
                                   x.data<float>(), gy.data<float>(), a.in[3].data<float>(),
                                   a.in[4].data<float>(), partial.data<double>(), g, kChannelChunk,
                                   chunks, act_gate<float>(a)});
  Launch::launch(g.c, BatchNormBackwardSumsBody<float>{partial.data<double>(), sums.data<float>(),
                                                       g.c, chunks});
  Launch::launch(x.numel(),
                 BatchNormBackwardDataBody<float>{
                     gy.data<float>(), x.data<float>(), data_or_null<float>(a.in[2]),
                     a.in[3].data<float>(), a.in[4].data<float>(), sums.data<float>(), out(0),
                     out(1), out(2), g, a.p<BatchNormParams>().training, act_gate<float>(a)});
}

template <class Launch>
void max_pool2d_op(const KernelArgs& a) {
  const Tensor &x = a.in[0], &y = a.out[0];
  Launch::launch(y.numel(), MaxPoolBody<float>{x.data<float>(), y.data<float>(),
                                               pool_geometry(x, y, a.p<Pool2dParams>())});
}

template <class Launch>
void max_pool2d_backward_op(const KernelArgs& a) {
  const Tensor &gy = a.in[0], &x = a.in[1], &gx = a.out[0];
  Launch::launch(gx.numel(),
                 MaxPoolBackwardBody<float>{gy.data<float>(), x.data<float>(), gx.data<float>(),
                                            pool_geometry(x, gy, a.p<Pool2dParams>())});
}

template <class Launch>
void avg_pool2d_op(const KernelArgs& a) {
  const Tensor &x = a.in[0], &y = a.out[0];
  Launch::launch(y.numel(), AvgPoolBody<float>{x.data<float>(), y.data<float>(),
                                               pool_geometry(x, y, a.p<Pool2dParams>())});
}

template <class Launch>
void avg_pool2d_backward_op(const KernelArgs& a) {
  const Tensor &gy = a.in[0], &gx = a.out[0];
  Launch::launch(gx.numel(),
                 AvgPoolBackwardBody<float>{gy.data<float>(), gx.data<float>(),
                                            pool_geometry(gx, gy, a.p<Pool2dParams>())});
}

}  // namespace cvd::cuda
