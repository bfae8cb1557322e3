// CUDA kernel bodies and op drivers of 2-D convolution and transposed convolution, forward and
// both backward passes (groups, dilation, asymmetric padding; PyTorch semantics), as direct
// gather kernels: every thread computes one output element from the (input pixel, output pixel,
// weight tap) triples linked by  in_pos = out_pos * stride - pad_before + tap * dilation.
// A transposed convolution is the adjoint of the convolution whose "output side" is its input,
// so the same three bodies serve both ops (see the drivers). No atomics, no shared memory:
// correct everywhere, not tuned (an im2col + cuBLAS / cuDNN path is future work).
#pragma once
#include "engine/dispatch.h"
#include "engine/kernel_params.h"
#include "kernels/cuda/launch_body.h"
#include "kernels/cuda/layout_body.h"

namespace cvd::cuda {

// The convolution in_side [N, C, H, W] -> out_side [N, O, OH, OW] with weight [O, C/g, KH, KW].
struct ConvGeometry {
  int64_t n, c, h, w;
  int64_t o, oh, ow;
  int64_t kh, kw, groups;
  int64_t stride_h, stride_w, pad_top, pad_left, dil_h, dil_w;
  CVD_HOST_DEVICE int64_t cpg() const { return c / groups; }
  CVD_HOST_DEVICE int64_t opg() const { return o / groups; }
};

template <class P>
ConvGeometry conv_geometry(const Tensor& in_side, const Tensor& w, const Tensor& out_side,
                           const P& p) {
  ConvGeometry g{};
  g.n = in_side.shape()[0], g.c = in_side.shape()[1], g.h = in_side.shape()[2];
  g.w = in_side.shape()[3];
  g.o = out_side.shape()[1], g.oh = out_side.shape()[2], g.ow = out_side.shape()[3];
  g.kh = w.shape()[2], g.kw = w.shape()[3], g.groups = p.groups;
  g.stride_h = p.stride_h, g.stride_w = p.stride_w, g.pad_top = p.pad_top;
  g.pad_left = p.pad_left, g.dil_h = p.dilation_h, g.dil_w = p.dilation_w;
  return g;
}

// out[n, o, oh, ow] = sum_{kc, kh, kw} in[n, c, ih, iw] * w[o, kc, kh, kw] (+ bias[o]).
template <class T>
struct ConvForwardBody {
  const T *in, *w, *bias;
  T* out;
  ConvGeometry g;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    const int64_t ow = i % g.ow, oh = (i / g.ow) % g.oh, o = (i / (g.ow * g.oh)) % g.o;
    const int64_t n = i / (g.ow * g.oh * g.o);
    const int64_t c0 = (o / g.opg()) * g.cpg();
    T acc = bias ? bias[o] : T(0);
    for (int64_t kc = 0; kc < g.cpg(); ++kc) {
      const T* plane = in + (n * g.c + c0 + kc) * g.h * g.w;
      const T* taps = w + (o * g.cpg() + kc) * g.kh * g.kw;
      for (int64_t kh = 0; kh < g.kh; ++kh) {
        const int64_t ih = oh * g.stride_h - g.pad_top + kh * g.dil_h;
        if (ih < 0 || ih >= g.h) continue;
        for (int64_t kw = 0; kw < g.kw; ++kw) {
          const int64_t iw = ow * g.stride_w - g.pad_left + kw * g.dil_w;
          if (iw < 0 || iw >= g.w) continue;
          acc += plane[ih * g.w + iw] * taps[kh * g.kw + kw];
        }
      }
    }
    out[i] = acc;
  }
};

// in_grad[n, c, ih, iw] = sum over (o, kh, kw) reaching (ih, iw) of out_grad[n, o, oh, ow] *
// w[o, kc, kh, kw] (+ bias[c]: the transposed convolution's bias).
template <class T>
struct ConvBackwardDataBody {
  const T *out_grad, *w, *bias;
  T* in_grad;
  ConvGeometry g;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    const int64_t iw = i % g.w, ih = (i / g.w) % g.h, c = (i / (g.w * g.h)) % g.c;
    const int64_t n = i / (g.w * g.h * g.c);
    const int64_t group = c / g.cpg(), kc = c % g.cpg();
    T acc = bias ? bias[c] : T(0);
    for (int64_t o = group * g.opg(); o < (group + 1) * g.opg(); ++o) {
      const T* plane = out_grad + (n * g.o + o) * g.oh * g.ow;
      const T* taps = w + (o * g.cpg() + kc) * g.kh * g.kw;
      for (int64_t kh = 0; kh < g.kh; ++kh) {
        const int64_t th = ih + g.pad_top - kh * g.dil_h;
        if (th < 0 || th % g.stride_h != 0 || th / g.stride_h >= g.oh) continue;
        const int64_t oh = th / g.stride_h;
        for (int64_t kw = 0; kw < g.kw; ++kw) {
          const int64_t tw = iw + g.pad_left - kw * g.dil_w;
          if (tw < 0 || tw % g.stride_w != 0 || tw / g.stride_w >= g.ow) continue;
          acc += plane[oh * g.ow + tw / g.stride_w] * taps[kh * g.kw + kw];
        }
      }
    }
    in_grad[i] = acc;
  }
};

// gw[o, kc, kh, kw] = sum_{n, oh, ow} out_grad[n, o, oh, ow] * in[n, c, ih, iw], split over the
// N * OH output rows into `chunks` chunks of `rows` rows: thread t = (weight element, chunk)
// writes its partial sum to partial[t] (double), added up by PartialSumBody (layout_body.h).
template <class T>
struct ConvBackwardWeightBody {
  const T *out_grad, *in;
  double* partial;
  ConvGeometry g;
  int64_t rows, chunks;
  CVD_HOST_DEVICE void operator()(int64_t t) const {
    const int64_t i = t / chunks, chunk = t % chunks;
    const int64_t kw = i % g.kw, kh = (i / g.kw) % g.kh, kc = (i / (g.kw * g.kh)) % g.cpg();
    const int64_t o = i / (g.kw * g.kh * g.cpg());
    const int64_t c = (o / g.opg()) * g.cpg() + kc;
    const int64_t row_end = (chunk + 1) * rows < g.n * g.oh ? (chunk + 1) * rows : g.n * g.oh;
    double acc = 0.0;
    for (int64_t row = chunk * rows; row < row_end; ++row) {
      const int64_t n = row / g.oh, oh = row % g.oh;
      const int64_t ih = oh * g.stride_h - g.pad_top + kh * g.dil_h;
      if (ih < 0 || ih >= g.h) continue;
      const T* go = out_grad + ((n * g.o + o) * g.oh + oh) * g.ow;
      const T* in_row = in + ((n * g.c + c) * g.h + ih) * g.w;
      for (int64_t ow = 0; ow < g.ow; ++ow) {
        const int64_t iw = ow * g.stride_w - g.pad_left + kw * g.dil_w;
        if (iw < 0 || iw >= g.w) continue;
        acc += static_cast<double>(go[ow]) * in_row[iw];
      }
    }
    partial[t] = acc;
  }
};

// gb[c] = sum over n and pixels of gy[n, c, :] (bias gradient of both convolutions).
template <class T>
struct ChannelSumBody {
  const T* gy;
  T* gb;
  int64_t n, c, inner;
  CVD_HOST_DEVICE void operator()(int64_t ch) const {
    double acc = 0.0;
    for (int64_t b = 0; b < n; ++b)
      for (int64_t i = 0; i < inner; ++i) acc += gy[(b * c + ch) * inner + i];
    gb[ch] = static_cast<T>(acc);
  }
};

// ---- Op drivers ---------------------------------------------------------------------------------

inline const float* optional_input(const KernelArgs& a, size_t k) {
  return k < a.in.size() ? data_or_null<float>(a.in[k]) : nullptr;
}

template <class Launch>
void bias_gradient(const KernelArgs& a) {
  if (a.out.size() < 2 || !a.out[1].defined()) return;
  const Tensor& gy = a.in[0];
  Launch::launch(gy.shape()[1],
                 ChannelSumBody<float>{gy.data<float>(), a.out[1].data<float>(), gy.shape()[0],
                                       gy.shape()[1], gy.shape()[2] * gy.shape()[3]});
}

// gw = the weight gradient of the convolution g (out_grad on its output side, in on its input
// side), in chunks of about 4096 multiply-adds per thread.
template <class Launch>
void conv_weight_gradient(const Tensor& out_grad, const Tensor& in, const Tensor& gw,
                          const ConvGeometry& g) {
  const int64_t rows = g.ow >= 4096 ? 1 : 4096 / (g.ow > 0 ? g.ow : 1);
  const int64_t total_rows = g.n * g.oh;
  const int64_t chunks = total_rows == 0 ? 1 : (total_rows + rows - 1) / rows;
  const Tensor partial = Tensor::empty({gw.numel() * chunks}, DType::f64, gw.device());
  Launch::launch(gw.numel() * chunks,
                 ConvBackwardWeightBody<float>{out_grad.data<float>(), in.data<float>(),
                                               partial.data<double>(), g, rows, chunks});
  Launch::launch(gw.numel(),
                 PartialSumBody<float>{partial.data<double>(), gw.data<float>(), chunks});
}

// in {x, w, b?}, out {y}.
template <class Launch>
void conv2d_op(const KernelArgs& a) {
  const Tensor &x = a.in[0], &w = a.in[1], &y = a.out[0];
  Launch::launch(y.numel(), ConvForwardBody<float>{x.data<float>(), w.data<float>(),
                                                   optional_input(a, 2), y.data<float>(),
                                                   conv_geometry(x, w, y, a.p<Conv2dParams>())});
}

// in {gy, w}, out {gx}.
template <class Launch>
void conv2d_backward_data_op(const KernelArgs& a) {
  const Tensor &gy = a.in[0], &w = a.in[1], &gx = a.out[0];
  Launch::launch(gx.numel(), ConvBackwardDataBody<float>{
                                 gy.data<float>(), w.data<float>(), nullptr, gx.data<float>(),
                                 conv_geometry(gx, w, gy, a.p<Conv2dParams>())});
}

// in {gy, x}, out {gw, gb?}.
template <class Launch>
void conv2d_backward_weight_op(const KernelArgs& a) {
  const Tensor &gy = a.in[0], &x = a.in[1], &gw = a.out[0];
  if (gw.defined()) {
    conv_weight_gradient<Launch>(gy, x, gw, conv_geometry(x, gw, gy, a.p<Conv2dParams>()));
  }
  bias_gradient<Launch>(a);
}

// in {x [N,Cin,H,W], w [Cin,Cout/g,KH,KW], b?}, out {y}: the adjoint of the convolution y -> x.
template <class Launch>
void conv_transpose2d_op(const KernelArgs& a) {
  const Tensor &x = a.in[0], &w = a.in[1], &y = a.out[0];
  Launch::launch(y.numel(),
                 ConvBackwardDataBody<float>{x.data<float>(), w.data<float>(), optional_input(a, 2),
                                             y.data<float>(),
                                             conv_geometry(y, w, x, a.p<ConvTranspose2dParams>())});
}

// in {gy, w}, out {gx}: the convolution gy -> gx.
template <class Launch>
void conv_transpose2d_backward_data_op(const KernelArgs& a) {
  const Tensor &gy = a.in[0], &w = a.in[1], &gx = a.out[0];
  Launch::launch(gx.numel(), ConvForwardBody<float>{
                                 gy.data<float>(), w.data<float>(), nullptr, gx.data<float>(),
                                 conv_geometry(gy, w, gx, a.p<ConvTranspose2dParams>())});
}

// in {gy, x}, out {gw, gb?}.
template <class Launch>
void conv_transpose2d_backward_weight_op(const KernelArgs& a) {
  const Tensor &gy = a.in[0], &x = a.in[1], &gw = a.out[0];
  if (gw.defined()) {
    conv_weight_gradient<Launch>(x, gy, gw, conv_geometry(gy, gw, x, a.p<ConvTranspose2dParams>()));
  }
  bias_gradient<Launch>(a);
}

}  // namespace cvd::cuda
