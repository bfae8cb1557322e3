// Reference kernels of 2-D convolution and transposed convolution, forward and backward (data,
// weight, bias), PyTorch semantics: cross-correlation, groups, dilation, asymmetric padding.
//
// Both ops are written as one loop over (input pixel, output pixel, weight tap) triples linked
// by   out_pos = in_pos * stride - pad_before + tap * dilation   (transposed convolution), or
//      in_pos  = out_pos * stride - pad_before + tap * dilation   (convolution),
// and each backward kernel visits exactly the same triples as its forward, so every gradient is
// the adjoint of its forward by construction.
#include "engine/kernel_params.h"
#include "kernels/reference/reference_access.h"
#include "kernels/reference/reference_kernels.h"

namespace cvd::reference {

namespace {

// Geometry of a convolution y = conv(x, w) with x [N, C, H, W], w [O, C/g, KH, KW],
// y [N, O, OH, OW]. For a transposed convolution the roles swap: x is the convolution's output
// side (its input [N, C, H, W] plays "y") and y its input side; see the transposed kernels.
struct ConvGeometry {
  int64_t n, c, h, w;  // the "input" side (the convolution's x)
  int64_t o, oh, ow;   // the "output" side (the convolution's y)
  int64_t kh, kw, groups;
  int64_t stride_h, stride_w, pad_top, pad_left, dil_h, dil_w;
  int64_t c_per_group() const { return c / groups; }
  int64_t o_per_group() const { return o / groups; }
};

void zero(const Tensor& t) {
  double* p = t.data<double>();
  for (int64_t i = 0; i < t.numel(); ++i) p[i] = 0.0;
}

// Calls f(ni, ci, ih, iw, oi, ohi, owi, kci, khi, kwi) for every input pixel (ni, ci, ih, iw)
// that weight tap (oi, kci, khi, kwi) connects to output pixel (ni, oi, ohi, owi) in the
// convolution described by g: ci = group * C/g + kci, ih = ohi * stride - pad + khi * dilation.
template <class F>
void for_each_conv_tap(const ConvGeometry& g, F&& f) {
  for (int64_t ni = 0; ni < g.n; ++ni) {
    for (int64_t oi = 0; oi < g.o; ++oi) {
      const int64_t group = oi / g.o_per_group();
      for (int64_t ohi = 0; ohi < g.oh; ++ohi) {
        for (int64_t owi = 0; owi < g.ow; ++owi) {
          for (int64_t kci = 0; kci < g.c_per_group(); ++kci) {
            const int64_t ci = group * g.c_per_group() + kci;
            for (int64_t khi = 0; khi < g.kh; ++khi) {
              const int64_t ih = ohi * g.stride_h - g.pad_top + khi * g.dil_h;
              if (ih < 0 || ih >= g.h) continue;
              for (int64_t kwi = 0; kwi < g.kw; ++kwi) {
                const int64_t iw = owi * g.stride_w - g.pad_left + kwi * g.dil_w;
                if (iw < 0 || iw >= g.w) continue;
                f(ni, ci, ih, iw, oi, ohi, owi, kci, khi, kwi);
              }
            }
          }
        }
      }
    }
  }
}

// Convolution geometry from x [N,C,H,W], w [O,C/g,KH,KW] and y [N,O,OH,OW]; checks that y has
// the size the parameters imply.
ConvGeometry conv_geometry(const Tensor& x, const Tensor& w, const Tensor& y,
                           const Conv2dParams& p) {
  CVD_ASSERT(x.dim() == 4 && w.dim() == 4 && y.dim() == 4);
  CVD_ASSERT(p.groups >= 1 && p.stride_h >= 1 && p.stride_w >= 1);
  CVD_ASSERT(p.dilation_h >= 1 && p.dilation_w >= 1);
  CVD_ASSERT(p.pad_top >= 0 && p.pad_bottom >= 0 && p.pad_left >= 0 && p.pad_right >= 0);
  ConvGeometry g{};
  g.n = x.shape()[0], g.c = x.shape()[1], g.h = x.shape()[2], g.w = x.shape()[3];
  g.o = w.shape()[0], g.kh = w.shape()[2], g.kw = w.shape()[3], g.groups = p.groups;
  g.oh = y.shape()[2], g.ow = y.shape()[3];
  g.stride_h = p.stride_h, g.stride_w = p.stride_w, g.pad_top = p.pad_top;
  g.pad_left = p.pad_left, g.dil_h = p.dilation_h, g.dil_w = p.dilation_w;
  CVD_ASSERT(g.c % g.groups == 0 && g.o % g.groups == 0);
  CVD_ASSERT(w.shape()[1] == g.c / g.groups);
  CVD_ASSERT(y.shape()[0] == g.n && y.shape()[1] == g.o);
  const int64_t span_h = g.h + p.pad_top + p.pad_bottom - g.dil_h * (g.kh - 1) - 1;
  const int64_t span_w = g.w + p.pad_left + p.pad_right - g.dil_w * (g.kw - 1) - 1;
  CVD_ASSERT(span_h >= 0 && span_w >= 0);
  CVD_ASSERT(g.oh == span_h / g.stride_h + 1 && g.ow == span_w / g.stride_w + 1);
  return g;
}

// Transposed-convolution geometry from its input x [N,C,H,W], weight w [C,O/g,KH,KW] and
// output y [N,O,OH,OW], expressed as the convolution that maps y-shaped tensors to x-shaped
// ones (whose adjoint it is): ConvGeometry's "input" side is y, its "output" side is x.
ConvGeometry conv_transpose_geometry(const Tensor& x, const Tensor& w, const Tensor& y,
                                     const ConvTranspose2dParams& p) {
  CVD_ASSERT(x.dim() == 4 && w.dim() == 4 && y.dim() == 4);
  CVD_ASSERT(p.groups >= 1 && p.stride_h >= 1 && p.stride_w >= 1);
  CVD_ASSERT(p.dilation_h >= 1 && p.dilation_w >= 1);
  CVD_ASSERT(p.pad_top >= 0 && p.pad_bottom >= 0 && p.pad_left >= 0 && p.pad_right >= 0);
  CVD_ASSERT(p.output_padding_h >= 0 && p.output_padding_w >= 0);
  ConvGeometry g{};
  g.n = x.shape()[0], g.o = x.shape()[1], g.oh = x.shape()[2], g.ow = x.shape()[3];
  g.c = y.shape()[1], g.h = y.shape()[2], g.w = y.shape()[3];
  g.kh = w.shape()[2], g.kw = w.shape()[3], g.groups = p.groups;
  g.stride_h = p.stride_h, g.stride_w = p.stride_w, g.pad_top = p.pad_top;
  g.pad_left = p.pad_left, g.dil_h = p.dilation_h, g.dil_w = p.dilation_w;
  CVD_ASSERT(g.o % g.groups == 0 && g.c % g.groups == 0);
  CVD_ASSERT(w.shape()[0] == g.o && w.shape()[1] == g.c / g.groups);
  CVD_ASSERT(y.shape()[0] == g.n);
  CVD_ASSERT(g.h == (g.oh - 1) * g.stride_h - p.pad_top - p.pad_bottom + g.dil_h * (g.kh - 1) +
                        p.output_padding_h + 1);
  CVD_ASSERT(g.w == (g.ow - 1) * g.stride_w - p.pad_left - p.pad_right + g.dil_w * (g.kw - 1) +
                        p.output_padding_w + 1);
  return g;
}

// Index helpers for NCHW tensors and [A, B, KH, KW] weights.
inline int64_t at4(const Shape& s, int64_t i0, int64_t i1, int64_t i2, int64_t i3) {
  return ((i0 * s[1] + i1) * s[2] + i2) * s[3] + i3;
}

// gb[c] = sum of gy over n, h, w (the bias gradient of both convolutions).
void bias_gradient(const Tensor& gy, const Tensor& gb) {
  CVD_ASSERT(is_f64_contiguous(gb) && gb.dim() == 1 && gb.shape()[0] == gy.shape()[1]);
  const Shape& s = gy.shape();
  const double* gyp = gy.data<double>();
  double* gbp = gb.data<double>();
  for (int64_t c = 0; c < s[1]; ++c) {
    double acc = 0.0;
    for (int64_t n = 0; n < s[0]; ++n) {
      for (int64_t i = 0; i < s[2] * s[3]; ++i) acc += gyp[(n * s[1] + c) * s[2] * s[3] + i];
    }
    gbp[c] = acc;
  }
}

// Adds b[c] to every pixel of channel c of y.
void add_bias(const Tensor& b, const Tensor& y) {
  CVD_ASSERT(is_f64_contiguous(b) && b.dim() == 1 && b.shape()[0] == y.shape()[1]);
  const Shape& s = y.shape();
  const double* bp = b.data<double>();
  double* yp = y.data<double>();
  for (int64_t n = 0; n < s[0]; ++n) {
    for (int64_t c = 0; c < s[1]; ++c) {
      for (int64_t i = 0; i < s[2] * s[3]; ++i) yp[(n * s[1] + c) * s[2] * s[3] + i] += bp[c];
    }
  }
}

}  // namespace

// in {x [N,C,H,W], w [O,C/g,KH,KW], b [O]?}, out {y [N,O,OH,OW]}; Conv2dParams.
void conv2d(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 3 && a.out.size() == 1 && a.params != nullptr);
  const Tensor& x = a.in[0];
  const Tensor& w = a.in[1];
  const Tensor& b = a.in[2];
  const Tensor& y = a.out[0];
  CVD_ASSERT(is_f64_contiguous(x) && is_f64_contiguous(w) && is_f64_contiguous(y));
  const ConvGeometry g = conv_geometry(x, w, y, a.p<Conv2dParams>());
  const double* xp = x.data<double>();
  const double* wp = w.data<double>();
  double* yp = y.data<double>();
  zero(y);
  for_each_conv_tap(g, [&](int64_t n, int64_t c, int64_t ih, int64_t iw, int64_t o, int64_t oh,
                           int64_t ow, int64_t kc, int64_t kh, int64_t kw) {
    yp[at4(y.shape(), n, o, oh, ow)] +=
        xp[at4(x.shape(), n, c, ih, iw)] * wp[at4(w.shape(), o, kc, kh, kw)];
  });
  if (b.defined()) add_bias(b, y);
}

// in {gy [N,O,OH,OW], w}, out {gx [N,C,H,W]}.
void conv2d_backward_data(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 2 && a.out.size() == 1 && a.params != nullptr);
  const Tensor& gy = a.in[0];
  const Tensor& w = a.in[1];
  const Tensor& gx = a.out[0];
  CVD_ASSERT(is_f64_contiguous(gy) && is_f64_contiguous(w) && is_f64_contiguous(gx));
  const ConvGeometry g = conv_geometry(gx, w, gy, a.p<Conv2dParams>());
  const double* gyp = gy.data<double>();
  const double* wp = w.data<double>();
  double* gxp = gx.data<double>();
  zero(gx);
  for_each_conv_tap(g, [&](int64_t n, int64_t c, int64_t ih, int64_t iw, int64_t o, int64_t oh,
                           int64_t ow, int64_t kc, int64_t kh, int64_t kw) {
    gxp[at4(gx.shape(), n, c, ih, iw)] +=
        gyp[at4(gy.shape(), n, o, oh, ow)] * wp[at4(w.shape(), o, kc, kh, kw)];
  });
}

// in {gy [N,O,OH,OW], x [N,C,H,W]}, out {gw [O,C/g,KH,KW], gb [O]?}.
void conv2d_backward_weight(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 2 && a.out.size() == 2 && a.params != nullptr);
  const Tensor& gy = a.in[0];
  const Tensor& x = a.in[1];
  const Tensor& gw = a.out[0];
  const Tensor& gb = a.out[1];
  CVD_ASSERT(is_f64_contiguous(gy) && is_f64_contiguous(x) && is_f64_contiguous(gw));
  const ConvGeometry g = conv_geometry(x, gw, gy, a.p<Conv2dParams>());
  const double* gyp = gy.data<double>();
  const double* xp = x.data<double>();
  double* gwp = gw.data<double>();
  zero(gw);
  for_each_conv_tap(g, [&](int64_t n, int64_t c, int64_t ih, int64_t iw, int64_t o, int64_t oh,
                           int64_t ow, int64_t kc, int64_t kh, int64_t kw) {
    gwp[at4(gw.shape(), o, kc, kh, kw)] +=
        gyp[at4(gy.shape(), n, o, oh, ow)] * xp[at4(x.shape(), n, c, ih, iw)];
  });
  if (gb.defined()) bias_gradient(gy, gb);
}

// in {x [N,C,H,W], w [C,O/g,KH,KW], b [O]?}, out {y [N,O,OH,OW]}; ConvTranspose2dParams.
// y is the adjoint of a convolution from y-shaped to x-shaped tensors with the same weight:
// y[n, o, ih*s - pad + kh*d] += x[n, c, ih] * w[c, o % (O/g), kh] (rows beyond the output, i.e.
// cropped by padding, are dropped; output_padding rows only receive what reaches them).
void conv_transpose2d(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 3 && a.out.size() == 1 && a.params != nullptr);
  const Tensor& x = a.in[0];
  const Tensor& w = a.in[1];
  const Tensor& b = a.in[2];
  const Tensor& y = a.out[0];
  CVD_ASSERT(is_f64_contiguous(x) && is_f64_contiguous(w) && is_f64_contiguous(y));
  const ConvGeometry g = conv_transpose_geometry(x, w, y, a.p<ConvTranspose2dParams>());
  const double* xp = x.data<double>();
  const double* wp = w.data<double>();
  double* yp = y.data<double>();
  zero(y);
  // In g, (c, ih, iw) index y and (o, oh, ow) index x; the weight tap is w[o][kc][kh][kw].
  for_each_conv_tap(g, [&](int64_t n, int64_t c, int64_t ih, int64_t iw, int64_t o, int64_t oh,
                           int64_t ow, int64_t kc, int64_t kh, int64_t kw) {
    yp[at4(y.shape(), n, c, ih, iw)] +=
        xp[at4(x.shape(), n, o, oh, ow)] * wp[at4(w.shape(), o, kc, kh, kw)];
  });
  if (b.defined()) add_bias(b, y);
}

// in {gy [N,O,OH,OW], w [C,O/g,KH,KW]}, out {gx [N,C,H,W]}.
void conv_transpose2d_backward_data(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 2 && a.out.size() == 1 && a.params != nullptr);
  const Tensor& gy = a.in[0];
  const Tensor& w = a.in[1];
  const Tensor& gx = a.out[0];
  CVD_ASSERT(is_f64_contiguous(gy) && is_f64_contiguous(w) && is_f64_contiguous(gx));
  const ConvGeometry g = conv_transpose_geometry(gx, w, gy, a.p<ConvTranspose2dParams>());
  const double* gyp = gy.data<double>();
  const double* wp = w.data<double>();
  double* gxp = gx.data<double>();
  zero(gx);
  for_each_conv_tap(g, [&](int64_t n, int64_t c, int64_t ih, int64_t iw, int64_t o, int64_t oh,
                           int64_t ow, int64_t kc, int64_t kh, int64_t kw) {
    gxp[at4(gx.shape(), n, o, oh, ow)] +=
        gyp[at4(gy.shape(), n, c, ih, iw)] * wp[at4(w.shape(), o, kc, kh, kw)];
  });
}

// in {gy [N,O,OH,OW], x [N,C,H,W]}, out {gw [C,O/g,KH,KW], gb [O]?}.
void conv_transpose2d_backward_weight(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 2 && a.out.size() == 2 && a.params != nullptr);
  const Tensor& gy = a.in[0];
  const Tensor& x = a.in[1];
  const Tensor& gw = a.out[0];
  const Tensor& gb = a.out[1];
  CVD_ASSERT(is_f64_contiguous(gy) && is_f64_contiguous(x) && is_f64_contiguous(gw));
  const ConvGeometry g = conv_transpose_geometry(x, gw, gy, a.p<ConvTranspose2dParams>());
  const double* gyp = gy.data<double>();
  const double* xp = x.data<double>();
  double* gwp = gw.data<double>();
  zero(gw);
  for_each_conv_tap(g, [&](int64_t n, int64_t c, int64_t ih, int64_t iw, int64_t o, int64_t oh,
                           int64_t ow, int64_t kc, int64_t kh, int64_t kw) {
    gwp[at4(gw.shape(), o, kc, kh, kw)] +=
        gyp[at4(gy.shape(), n, c, ih, iw)] * xp[at4(x.shape(), n, o, oh, ow)];
  });
  if (gb.defined()) bias_gradient(gy, gb);
}

}  // namespace cvd::reference
