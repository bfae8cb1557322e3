// CUDA kernel bodies and op drivers of resampling: bilinear resize (both align_corners modes),
// bicubic and nearest resize, forward and backward, and bilinear grid_sample (zeros / border padding),
// forward and backward. PyTorch semantics; the taps are engine/resample_math.h, shared with
// the CPU kernels. The resize backward kernels are gathers (one thread per input pixel visits the
// output pixels whose taps reach it), so they need no atomics and are deterministic; the
// grid_sample backward scatters into gx with atomic_add (grid positions are arbitrary).
#pragma once
#include <cmath>

#include "engine/dispatch.h"
#include "engine/kernel_params.h"
#include "engine/resample_math.h"
#include "kernels/cuda/launch_body.h"

namespace cvd::cuda {

// Planes [P, H, W] (input side) and [P, OH, OW] (output side) of a resize.
struct ResizeGeometry {
  int64_t planes, h, w, oh, ow;
};

inline ResizeGeometry resize_geometry(const Tensor& x, const Tensor& y) {
  return {x.shape()[0] * x.shape()[1], x.shape()[2], x.shape()[3], y.shape()[2], y.shape()[3]};
}

template <class T>
struct BilinearResizeBody {
  const T* x;
  T* y;
  ResizeGeometry g;
  bool align_corners;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    const int64_t c = i % g.ow, r = (i / g.ow) % g.oh, pl = i / (g.ow * g.oh);
    const LinearResizeTaps<T> th = resize_linear_taps<T>(r, g.h, g.oh, align_corners);
    const LinearResizeTaps<T> tw = resize_linear_taps<T>(c, g.w, g.ow, align_corners);
    const T* p = x + pl * g.h * g.w;
    y[i] = th.w0 * (tw.w0 * p[th.i0 * g.w + tw.i0] + tw.w1 * p[th.i0 * g.w + tw.i1]) +
           th.w1 * (tw.w0 * p[th.i1 * g.w + tw.i0] + tw.w1 * p[th.i1 * g.w + tw.i1]);
  }
};

// Sum over the outputs o of one axis whose taps reach input index `in_index`, of
// weight(o) * f(o). Taps are monotone in o, so o runs from just below in_index * out / in until
// the first tap passes in_index.
template <class T, class F>
CVD_HOST_DEVICE T linear_adjoint_axis(int64_t in_index, int64_t in, int64_t out, bool align_corners,
                                      const F& f) {
  int64_t o = in_index >= 1 ? (in_index - 1) * out / in - 2 : 0;
  if (o < 0) o = 0;
  T acc = T(0);
  for (; o < out; ++o) {
    const LinearResizeTaps<T> t = resize_linear_taps<T>(o, in, out, align_corners);
    if (t.i0 > in_index) break;
    T wgt = T(0);
    if (t.i0 == in_index) wgt += t.w0;
    if (t.i1 == in_index) wgt += t.w1;
    if (wgt != T(0)) acc += wgt * f(o);
  }
  return acc;
}

// gx[pl, ih, iw] = sum over outputs (r, c) of wh(r) * ww(c) * gy[pl, r, c].
template <class T>
struct BilinearResizeBackwardBody {
  const T* gy;
  T* gx;
  ResizeGeometry g;
  bool align_corners;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    const int64_t iw = i % g.w, ih = (i / g.w) % g.h, pl = i / (g.w * g.h);
    const T* plane = gy + pl * g.oh * g.ow;
    const ResizeGeometry geo = g;
    const bool ac = align_corners;
    gx[i] = linear_adjoint_axis<T>(ih, g.h, g.oh, ac, [&](int64_t r) {
      return linear_adjoint_axis<T>(iw, geo.w, geo.ow, ac,
                                    [&](int64_t c) { return plane[r * geo.ow + c]; });
    });
  }
};

template <class T>
struct NearestResizeBody {
  const T* x;
  T* y;
  ResizeGeometry g;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    const int64_t c = i % g.ow, r = (i / g.ow) % g.oh, pl = i / (g.ow * g.oh);
    y[i] = x[(pl * g.h + nearest_source_index(r, g.h, g.oh)) * g.w +
             nearest_source_index(c, g.w, g.ow)];
  }
};

// First output index along an axis whose nearest source may be `in_index` (a safe lower bound).
CVD_HOST_DEVICE int64_t nearest_adjoint_start(int64_t in_index, int64_t in, int64_t out) {
  const int64_t o = in_index * out / in - 2;
  return o < 0 ? 0 : o;
}

template <class T>
struct NearestResizeBackwardBody {
  const T* gy;
  T* gx;
  ResizeGeometry g;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    const int64_t iw = i % g.w, ih = (i / g.w) % g.h, pl = i / (g.w * g.h);
    const T* plane = gy + pl * g.oh * g.ow;
    T acc = T(0);
    for (int64_t r = nearest_adjoint_start(ih, g.h, g.oh); r < g.oh; ++r) {
      const int64_t sr = nearest_source_index(r, g.h, g.oh);
      if (sr > ih) break;
      if (sr != ih) continue;
      for (int64_t c = nearest_adjoint_start(iw, g.w, g.ow); c < g.ow; ++c) {
        const int64_t sc = nearest_source_index(c, g.w, g.ow);
        if (sc > iw) break;
        if (sc == iw) acc += plane[r * g.ow + c];
      }
    }
    gx[i] = acc;
  }
};

// The four bilinear corners of the pixel coordinate (ix, iy), as the reference grid_sample.
template <class T>
struct GridCorners {
  int64_t row[4], col[4];
  bool inside[4];
  T weight[4], dweight_dx[4], dweight_dy[4];
};

template <class T>
CVD_HOST_DEVICE GridCorners<T> grid_corners(T ix, T iy, int64_t h, int64_t w) {
  GridCorners<T> k;
  const T x0 = floor(ix), y0 = floor(iy);
  const T fx = ix - x0, fy = iy - y0;
  const T wx[2] = {T(1) - fx, fx}, wy[2] = {T(1) - fy, fy};
  const T dw[2] = {T(-1), T(1)};
  for (int c = 0; c < 4; ++c) {
    const int dy = c / 2, dx = c % 2;  // nw, ne, sw, se
    k.row[c] = static_cast<int64_t>(y0) + dy;
    k.col[c] = static_cast<int64_t>(x0) + dx;
    k.inside[c] = k.row[c] >= 0 && k.row[c] < h && k.col[c] >= 0 && k.col[c] < w;
    k.weight[c] = wx[dx] * wy[dy];
    k.dweight_dx[c] = dw[dx] * wy[dy];
    k.dweight_dy[c] = wx[dx] * dw[dy];
  }
  return k;
}

struct GridGeometry {
  int64_t n, c, h, w, oh, ow;
};

// One thread per output element y[n, ch, r, col].
template <class T>
struct GridSampleBody {
  const T *x, *grid;
  T* y;
  GridGeometry g;
  GridPadding padding;
  bool align_corners;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    const int64_t col = i % g.ow, r = (i / g.ow) % g.oh, ch = (i / (g.ow * g.oh)) % g.c;
    const int64_t n = i / (g.ow * g.oh * g.c);
    const T* gxy = grid + ((n * g.oh + r) * g.ow + col) * 2;
    T dx, dy;
    const T ix = grid_source_coord<T>(gxy[0], g.w, padding, align_corners, &dx);
    const T iy = grid_source_coord<T>(gxy[1], g.h, padding, align_corners, &dy);
    const GridCorners<T> k = grid_corners<T>(ix, iy, g.h, g.w);
    const T* plane = x + (n * g.c + ch) * g.h * g.w;
    T v = T(0);
    for (int c = 0; c < 4; ++c) {
      if (k.inside[c]) v += k.weight[c] * plane[k.row[c] * g.w + k.col[c]];
    }
    y[i] = v;
  }
};

// One thread per grid cell (n, r, col): loops over channels, writes ggrid, scatters into gx
// (atomic_add; gx must be zeroed first).
template <class T>
struct GridSampleBackwardBody {
  const T *gy, *x, *grid;
  T *gx, *ggrid;  // either may be nullptr
  GridGeometry g;
  GridPadding padding;
  bool align_corners;
  CVD_HOST_DEVICE void operator()(int64_t cell) const {
    const int64_t col = cell % g.ow, r = (cell / g.ow) % g.oh, n = cell / (g.ow * g.oh);
    T dposx, dposy;
    const T ix = grid_source_coord<T>(grid[cell * 2], g.w, padding, align_corners, &dposx);
    const T iy = grid_source_coord<T>(grid[cell * 2 + 1], g.h, padding, align_corners, &dposy);
    const GridCorners<T> k = grid_corners<T>(ix, iy, g.h, g.w);
    T d_ix = T(0), d_iy = T(0);
    for (int64_t ch = 0; ch < g.c; ++ch) {
      const int64_t plane = (n * g.c + ch) * g.h * g.w;
      const T go = gy[((n * g.c + ch) * g.oh + r) * g.ow + col];
      for (int c = 0; c < 4; ++c) {
        if (!k.inside[c]) continue;
        const int64_t idx = plane + k.row[c] * g.w + k.col[c];
        if (gx) atomic_add(gx + idx, k.weight[c] * go);
        d_ix += k.dweight_dx[c] * x[idx] * go;
        d_iy += k.dweight_dy[c] * x[idx] * go;
      }
    }
    if (ggrid) {
      ggrid[cell * 2] = d_ix * dposx;
      ggrid[cell * 2 + 1] = d_iy * dposy;
    }
  }
};

// Bicubic resize: one thread per output pixel, 16 clamped taps (PyTorch upsample_bicubic2d).
template <class T>
struct BicubicResizeBody {
  const T* x;
  T* y;
  ResizeGeometry g;
  UpsampleParams p;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    const int64_t c = i % g.ow, r = (i / g.ow) % g.oh, pl = i / (g.ow * g.oh);
    const CubicResizeTaps<T> th = resize_cubic_taps<T>(r, g.h, g.oh, p.align_corners, p.scale_h);
    const CubicResizeTaps<T> tw = resize_cubic_taps<T>(c, g.w, g.ow, p.align_corners, p.scale_w);
    const T* plane = x + pl * g.h * g.w;
    T acc = T(0);
    for (int a = 0; a < 4; ++a) {
      T s = T(0);
      for (int b = 0; b < 4; ++b) s += tw.w[b] * plane[th.i[a] * g.w + tw.i[b]];
      acc += th.w[a] * s;
    }
    y[i] = acc;
  }
};

// Bicubic backward: one thread per output pixel scatters its 16 weighted gradients into gx with
// atomic_add (clamped taps make the adjoint's reach irregular; gx is zeroed first). The order of
// the additions, and so the last bits, may differ between runs on a device.
template <class T>
struct BicubicResizeBackwardBody {
  const T* gy;
  T* gx;
  ResizeGeometry g;
  UpsampleParams p;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    const int64_t c = i % g.ow, r = (i / g.ow) % g.oh, pl = i / (g.ow * g.oh);
    const CubicResizeTaps<T> th = resize_cubic_taps<T>(r, g.h, g.oh, p.align_corners, p.scale_h);
    const CubicResizeTaps<T> tw = resize_cubic_taps<T>(c, g.w, g.ow, p.align_corners, p.scale_w);
    T* plane = gx + pl * g.h * g.w;
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b)
        atomic_add(plane + th.i[a] * g.w + tw.i[b], th.w[a] * tw.w[b] * gy[i]);
  }
};

// ---- Op drivers ---------------------------------------------------------------------------------

template <class Launch>
void upsample_bilinear2d_op(const KernelArgs& a) {
  const Tensor &x = a.in[0], &y = a.out[0];
  Launch::launch(y.numel(),
                 BilinearResizeBody<float>{x.data<float>(), y.data<float>(), resize_geometry(x, y),
                                           a.p<UpsampleParams>().align_corners});
}

template <class Launch>
void upsample_bilinear2d_backward_op(const KernelArgs& a) {
  const Tensor &gy = a.in[0], &gx = a.out[0];
  Launch::launch(gx.numel(), BilinearResizeBackwardBody<float>{
                                 gy.data<float>(), gx.data<float>(), resize_geometry(gx, gy),
                                 a.p<UpsampleParams>().align_corners});
}

template <class Launch>
void upsample_nearest2d_op(const KernelArgs& a) {
  const Tensor &x = a.in[0], &y = a.out[0];
  Launch::launch(y.numel(),
                 NearestResizeBody<float>{x.data<float>(), y.data<float>(), resize_geometry(x, y)});
}

template <class Launch>
void upsample_nearest2d_backward_op(const KernelArgs& a) {
  const Tensor &gy = a.in[0], &gx = a.out[0];
  Launch::launch(gx.numel(), NearestResizeBackwardBody<float>{gy.data<float>(), gx.data<float>(),
                                                              resize_geometry(gx, gy)});
}

template <class Launch>
void upsample_bicubic2d_op(const KernelArgs& a) {
  const Tensor &x = a.in[0], &y = a.out[0];
  Launch::launch(y.numel(), BicubicResizeBody<float>{x.data<float>(), y.data<float>(),
                                                     resize_geometry(x, y), a.p<UpsampleParams>()});
}

template <class T>
struct ZeroBody {
  T* p;
  CVD_HOST_DEVICE void operator()(int64_t i) const { p[i] = T(0); }
};

template <class Launch>
void upsample_bicubic2d_backward_op(const KernelArgs& a) {
  const Tensor &gy = a.in[0], &gx = a.out[0];
  Launch::launch(gx.numel(), ZeroBody<float>{gx.data<float>()});
  Launch::launch(gy.numel(),
                 BicubicResizeBackwardBody<float>{gy.data<float>(), gx.data<float>(),
                                                  resize_geometry(gx, gy), a.p<UpsampleParams>()});
}

inline GridGeometry grid_geometry(const Tensor& x, const Tensor& y) {
  return {x.shape()[0], x.shape()[1], x.shape()[2], x.shape()[3], y.shape()[2], y.shape()[3]};
}

template <class Launch>
void grid_sample_op(const KernelArgs& a) {
  const Tensor &x = a.in[0], &grid = a.in[1], &y = a.out[0];
  const GridSampleParams& p = a.p<GridSampleParams>();
  Launch::launch(y.numel(),
                 GridSampleBody<float>{x.data<float>(), grid.data<float>(), y.data<float>(),
                                       grid_geometry(x, y), p.padding, p.align_corners});
}

template <class Launch>
void grid_sample_backward_op(const KernelArgs& a) {
  const Tensor &gy = a.in[0], &x = a.in[1], &grid = a.in[2];
  const Tensor& gx = a.out[0];
  const Tensor& ggrid = a.out.size() > 1 ? a.out[1] : Tensor();
  const GridSampleParams& p = a.p<GridSampleParams>();
  if (gx.defined()) Launch::launch(gx.numel(), ZeroBody<float>{gx.data<float>()});
  const GridGeometry g = grid_geometry(x, gy);
  Launch::launch(g.n * g.oh * g.ow,
                 GridSampleBackwardBody<float>{
                     gy.data<float>(), x.data<float>(), grid.data<float>(), data_or_null<float>(gx),
                     data_or_null<float>(ggrid), g, p.padding, p.align_corners});
}

}  // namespace cvd::cuda
