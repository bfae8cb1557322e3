// Reference kernels of resampling: bilinear, bicubic and nearest upsampling (any output size,
// both align_corners modes) and bilinear grid_sample (zeros / border padding), forward and backward,
// PyTorch semantics. Each backward scatters through exactly the taps and weights of its forward.
#include <algorithm>
#include <cmath>

#include "engine/kernel_params.h"
#include "engine/resample_math.h"
#include "kernels/reference/reference_access.h"
#include "kernels/reference/reference_kernels.h"

namespace cvd::reference {

namespace {

// The two source taps of output index o along one axis and their weights (PyTorch upsample
// bilinear: i0 = floor(src), i1 = i0 + 1 clamped to the last index, w1 = src - i0).
struct LinearTaps {
  int64_t i0, i1;
  double w0, w1;
};

LinearTaps linear_taps(int64_t o, int64_t in, int64_t out, bool align_corners) {
  const double src = resize_source_coord<double>(o, in, out, align_corners);
  const int64_t i0 = std::min(static_cast<int64_t>(std::floor(src)), in - 1);
  const int64_t i1 = i0 < in - 1 ? i0 + 1 : i0;
  double w1 = src - static_cast<double>(i0);
  w1 = w1 < 0.0 ? 0.0 : (w1 > 1.0 ? 1.0 : w1);
  return {i0, i1, 1.0 - w1, w1};
}

// PyTorch "nearest": floor(o * scale) with PyTorch's float32 scale in / out (shared with the
// fast kernels, so sizes where float rounding moves the index agree with PyTorch).
int64_t nearest_source(int64_t o, int64_t in, int64_t out) {
  return nearest_source_index(o, in, out);
}

// x [N, C, H, W] and y [N, C, OH, OW] with equal N, C; returns N * C.
int64_t resize_planes(const Tensor& x, const Tensor& y) {
  CVD_ASSERT(is_f64_contiguous(x) && is_f64_contiguous(y) && x.dim() == 4 && y.dim() == 4);
  CVD_ASSERT(x.shape()[0] == y.shape()[0] && x.shape()[1] == y.shape()[1]);
  CVD_ASSERT(x.shape()[2] >= 1 && x.shape()[3] >= 1);
  return x.shape()[0] * x.shape()[1];
}

// Runs the bilinear resize from the big `in` plane to `out` (forward), or scatters `out` back
// into `in` (backward: in += taps^T out), plane by plane.
void bilinear(const Tensor& x, const Tensor& y, bool align_corners, bool backward) {
  const int64_t planes = resize_planes(x, y);
  const int64_t h = x.shape()[2], w = x.shape()[3], oh = y.shape()[2], ow = y.shape()[3];
  double* xp = x.data<double>();
  double* yp = y.data<double>();
  if (backward) {
    for (int64_t i = 0; i < x.numel(); ++i) xp[i] = 0.0;
  }
  for (int64_t pl = 0; pl < planes; ++pl) {
    double* xplane = xp + pl * h * w;
    double* yplane = yp + pl * oh * ow;
    for (int64_t r = 0; r < oh; ++r) {
      const LinearTaps th = linear_taps(r, h, oh, align_corners);
      for (int64_t c = 0; c < ow; ++c) {
        const LinearTaps tw = linear_taps(c, w, ow, align_corners);
        const int64_t idx[4] = {th.i0 * w + tw.i0, th.i0 * w + tw.i1, th.i1 * w + tw.i0,
                                th.i1 * w + tw.i1};
        const double wt[4] = {th.w0 * tw.w0, th.w0 * tw.w1, th.w1 * tw.w0, th.w1 * tw.w1};
        double& out = yplane[r * ow + c];
        if (backward) {
          for (int k = 0; k < 4; ++k) xplane[idx[k]] += wt[k] * out;
        } else {
          out = 0.0;
          for (int k = 0; k < 4; ++k) out += wt[k] * xplane[idx[k]];
        }
      }
    }
  }
}

// Nearest resize forward (y = x[src]) or backward (x += scatter of y), plane by plane.
void nearest(const Tensor& x, const Tensor& y, bool backward) {
  const int64_t planes = resize_planes(x, y);
  const int64_t h = x.shape()[2], w = x.shape()[3], oh = y.shape()[2], ow = y.shape()[3];
  double* xp = x.data<double>();
  double* yp = y.data<double>();
  if (backward) {
    for (int64_t i = 0; i < x.numel(); ++i) xp[i] = 0.0;
  }
  for (int64_t pl = 0; pl < planes; ++pl) {
    for (int64_t r = 0; r < oh; ++r) {
      const int64_t sr = nearest_source(r, h, oh);
      for (int64_t c = 0; c < ow; ++c) {
        const int64_t sc = nearest_source(c, w, ow);
        double& out = yp[(pl * oh + r) * ow + c];
        double& in = xp[(pl * h + sr) * w + sc];
        if (backward) {
          in += out;
        } else {
          out = in;
        }
      }
    }
  }
}

// Bicubic resize (PyTorch upsample_bicubic2d, A = -0.75, taps clamped to the border) forward, or
// its scatter back (in += taps^T out), plane by plane.
void bicubic(const Tensor& x, const Tensor& y, const UpsampleParams& p, bool backward) {
  const int64_t planes = resize_planes(x, y);
  const int64_t h = x.shape()[2], w = x.shape()[3], oh = y.shape()[2], ow = y.shape()[3];
  double* xp = x.data<double>();
  double* yp = y.data<double>();
  if (backward) {
    for (int64_t i = 0; i < x.numel(); ++i) xp[i] = 0.0;
  }
  for (int64_t pl = 0; pl < planes; ++pl) {
    double* xplane = xp + pl * h * w;
    double* yplane = yp + pl * oh * ow;
    for (int64_t r = 0; r < oh; ++r) {
      const CubicResizeTaps<double> th =
          resize_cubic_taps<double>(r, h, oh, p.align_corners, p.scale_h);
      for (int64_t c = 0; c < ow; ++c) {
        const CubicResizeTaps<double> tw =
            resize_cubic_taps<double>(c, w, ow, p.align_corners, p.scale_w);
        double& out = yplane[r * ow + c];
        if (!backward) out = 0.0;
        for (int i = 0; i < 4; ++i)
          for (int j = 0; j < 4; ++j) {
            double& in = xplane[th.i[i] * w + tw.i[j]];
            if (backward)
              in += th.w[i] * tw.w[j] * out;
            else
              out += th.w[i] * tw.w[j] * in;
          }
      }
    }
  }
}

}  // namespace

// in {x [N,C,H,W]}, out {y [N,C,OH,OW]}; UpsampleParams.
void upsample_bicubic2d(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1 && a.params != nullptr);
  bicubic(a.in[0], a.out[0], a.p<UpsampleParams>(), false);
}

// in {gy [N,C,OH,OW]}, out {gx [N,C,H,W]}; UpsampleParams.
void upsample_bicubic2d_backward(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1 && a.params != nullptr);
  bicubic(a.out[0], a.in[0], a.p<UpsampleParams>(), true);
}

// in {x [N,C,H,W]}, out {y [N,C,OH,OW]}; UpsampleParams.
void upsample_bilinear2d(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1 && a.params != nullptr);
  bilinear(a.in[0], a.out[0], a.p<UpsampleParams>().align_corners, false);
}

// in {gy [N,C,OH,OW]}, out {gx [N,C,H,W]}; UpsampleParams.
void upsample_bilinear2d_backward(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1 && a.params != nullptr);
  bilinear(a.out[0], a.in[0], a.p<UpsampleParams>().align_corners, true);
}

// in {x [N,C,H,W]}, out {y [N,C,OH,OW]}.
void upsample_nearest2d(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1);
  nearest(a.in[0], a.out[0], false);
}

// in {gy [N,C,OH,OW]}, out {gx [N,C,H,W]}.
void upsample_nearest2d_backward(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1);
  nearest(a.out[0], a.in[0], true);
}

namespace {

// One grid_sample sampling position along one axis: the pixel coordinate after padding, and
// d(coordinate)/d(normalised grid value).
struct GridCoord {
  double pos;
  double dpos;
};

GridCoord grid_coord(double g, int64_t size, const GridSampleParams& p) {
  // Border padding clips to [0, size - 1] with zero gradient at and beyond the limits (PyTorch).
  double dpos = 0.0;
  double pos = grid_source_coord<double>(g, size, p.padding, p.align_corners, &dpos);
  return {pos, dpos};
}

// The four bilinear corners of (ix, iy): pixel (row, col), weight, and the weight's derivatives
// with respect to ix and iy. Corners outside the image are flagged (they read 0).
struct GridCorner {
  int64_t row, col;
  bool inside;
  double weight, dweight_dx, dweight_dy;
};

void grid_corners(double ix, double iy, int64_t h, int64_t w, GridCorner corners[4]) {
  const double x0 = std::floor(ix), y0 = std::floor(iy);
  const double fx = ix - x0, fy = iy - y0;  // distance from the north-west corner
  const double wx[2] = {1.0 - fx, fx}, wy[2] = {1.0 - fy, fy};
  const double dwx[2] = {-1.0, 1.0}, dwy[2] = {-1.0, 1.0};
  for (int k = 0; k < 4; ++k) {
    const int dy = k / 2, dx = k % 2;  // nw, ne, sw, se
    GridCorner& c = corners[k];
    c.row = static_cast<int64_t>(y0) + dy;
    c.col = static_cast<int64_t>(x0) + dx;
    c.inside = c.row >= 0 && c.row < h && c.col >= 0 && c.col < w;
    c.weight = wx[dx] * wy[dy];
    c.dweight_dx = dwx[dx] * wy[dy];
    c.dweight_dy = wx[dx] * dwy[dy];
  }
}

struct GridGeometry {
  int64_t n, c, h, w, oh, ow;
};

GridGeometry grid_geometry(const Tensor& x, const Tensor& grid, const Tensor& y) {
  CVD_ASSERT(is_f64_contiguous(x) && is_f64_contiguous(grid) && is_f64_contiguous(y));
  CVD_ASSERT(x.dim() == 4 && grid.dim() == 4 && y.dim() == 4 && grid.shape()[3] == 2);
  CVD_ASSERT(grid.shape()[0] == x.shape()[0] && y.shape()[0] == x.shape()[0]);
  CVD_ASSERT(y.shape()[1] == x.shape()[1]);
  CVD_ASSERT(y.shape()[2] == grid.shape()[1] && y.shape()[3] == grid.shape()[2]);
  return {x.shape()[0], x.shape()[1], x.shape()[2], x.shape()[3], y.shape()[2], y.shape()[3]};
}

}  // namespace

// in {x [N,C,H,W], grid [N,OH,OW,2] (x, y) in [-1, 1]}, out {y [N,C,OH,OW]}; GridSampleParams.
void grid_sample(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 2 && a.out.size() == 1 && a.params != nullptr);
  const Tensor& x = a.in[0];
  const Tensor& grid = a.in[1];
  const Tensor& y = a.out[0];
  const GridSampleParams& p = a.p<GridSampleParams>();
  const GridGeometry g = grid_geometry(x, grid, y);
  const double* xp = x.data<double>();
  const double* gp = grid.data<double>();
  double* yp = y.data<double>();
  for (int64_t n = 0; n < g.n; ++n) {
    for (int64_t r = 0; r < g.oh; ++r) {
      for (int64_t col = 0; col < g.ow; ++col) {
        const double* gxy = gp + ((n * g.oh + r) * g.ow + col) * 2;
        const GridCoord cx = grid_coord(gxy[0], g.w, p), cy = grid_coord(gxy[1], g.h, p);
        GridCorner corners[4];
        grid_corners(cx.pos, cy.pos, g.h, g.w, corners);
        for (int64_t ch = 0; ch < g.c; ++ch) {
          const double* plane = xp + (n * g.c + ch) * g.h * g.w;
          double v = 0.0;
          for (const GridCorner& k : corners) {
            if (k.inside) v += k.weight * plane[k.row * g.w + k.col];
          }
          yp[((n * g.c + ch) * g.oh + r) * g.ow + col] = v;
        }
      }
    }
  }
}

// in {gy [N,C,OH,OW], x, grid}, out {gx [N,C,H,W]?, ggrid [N,OH,OW,2]?}; GridSampleParams.
void grid_sample_backward(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 3 && a.out.size() == 2 && a.params != nullptr);
  const Tensor& gy = a.in[0];
  const Tensor& x = a.in[1];
  const Tensor& grid = a.in[2];
  const Tensor& gx = a.out[0];
  const Tensor& ggrid = a.out[1];
  const GridSampleParams& p = a.p<GridSampleParams>();
  const GridGeometry g = grid_geometry(x, grid, gy);
  CVD_ASSERT(!gx.defined() || (is_f64_contiguous(gx) && gx.shape() == x.shape()));
  CVD_ASSERT(!ggrid.defined() || (is_f64_contiguous(ggrid) && ggrid.shape() == grid.shape()));
  const double* xp = x.data<double>();
  const double* gp = grid.data<double>();
  const double* gyp = gy.data<double>();
  double* gxp = gx.defined() ? gx.data<double>() : nullptr;
  double* ggp = ggrid.defined() ? ggrid.data<double>() : nullptr;
  if (gxp) {
    for (int64_t i = 0; i < gx.numel(); ++i) gxp[i] = 0.0;
  }
  for (int64_t n = 0; n < g.n; ++n) {
    for (int64_t r = 0; r < g.oh; ++r) {
      for (int64_t col = 0; col < g.ow; ++col) {
        const int64_t cell = (n * g.oh + r) * g.ow + col;
        const GridCoord cx = grid_coord(gp[cell * 2], g.w, p);
        const GridCoord cy = grid_coord(gp[cell * 2 + 1], g.h, p);
        GridCorner corners[4];
        grid_corners(cx.pos, cy.pos, g.h, g.w, corners);
        double d_ix = 0.0, d_iy = 0.0;  // d(loss)/d(pixel coordinates)
        for (int64_t ch = 0; ch < g.c; ++ch) {
          const int64_t plane = (n * g.c + ch) * g.h * g.w;
          const double go = gyp[((n * g.c + ch) * g.oh + r) * g.ow + col];
          for (const GridCorner& k : corners) {
            if (!k.inside) continue;
            const int64_t idx = plane + k.row * g.w + k.col;
            if (gxp) gxp[idx] += k.weight * go;
            d_ix += k.dweight_dx * xp[idx] * go;
            d_iy += k.dweight_dy * xp[idx] * go;
          }
        }
        if (ggp) {
          ggp[cell * 2] = d_ix * cx.dpos;
          ggp[cell * 2 + 1] = d_iy * cy.dpos;
        }
      }
    }
  }
}

}  // namespace cvd::reference
