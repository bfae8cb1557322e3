// Resampling coordinates and filter taps shared by every backend (resize, upsample, grid sample):
// the reference loops, the OpenMP CPU kernels and the CUDA kernels all call these functions.
#pragma once
#include <cmath>

#include "engine/elementwise_math.h"  // CVD_HOST_DEVICE
#include "engine/kernel_params.h"

namespace cvd {

// Source coordinate for resizing (see UpsampleParams).
template <class T>
CVD_HOST_DEVICE T resize_source_coord(long o, long in, long out, bool align_corners) {
  if (align_corners) return out > 1 ? T(o) * T(in - 1) / T(out - 1) : T(0);
  T s = (T(o) + T(0.5)) * T(in) / T(out) - T(0.5);
  return s < T(0) ? T(0) : s;
}

// grid_sample: normalised [-1, 1] coordinate to pixel coordinate, and its derivative.
template <class T>
CVD_HOST_DEVICE T grid_unnormalize(T g, long size, bool align_corners) {
  return align_corners ? (g + T(1)) / T(2) * T(size - 1) : ((g + T(1)) * T(size) - T(1)) / T(2);
}
template <class T>
CVD_HOST_DEVICE T grid_unnormalize_scale(long size, bool align_corners) {
  return align_corners ? T(size - 1) / T(2) : T(size) / T(2);
}

// ---- Resampling taps (PyTorch semantics), shared by the resize and grid_sample kernels ---------

// PyTorch "nearest" source index: floor(o * scale) with scale = in / out rounded to float, as
// PyTorch computes it (so in 2, out 82, o 41 gives 0 where exact arithmetic gives 1); o itself
// when out == in, o / 2 when out == 2 * in; clamped to in - 1.
CVD_HOST_DEVICE long nearest_source_index(long o, long in, long out) {
  if (out == in) return o;
  if (out == 2 * in) return o >> 1;
  const float scale = static_cast<float>(in) / static_cast<float>(out);
  const long i = static_cast<long>(floorf(static_cast<float>(o) * scale));
  return i < in - 1 ? i : in - 1;
}

// The two source taps of output index o along one axis of a bilinear resize (PyTorch
// upsample_bilinear2d): i0 = floor(src) clamped to in - 1, i1 = i0 + 1 clamped to in - 1, and
// their weights w0 = 1 - w1, w1 = src - i0 clamped to [0, 1].
template <class T>
struct LinearResizeTaps {
  long i0, i1;
  T w0, w1;
};
template <class T>
CVD_HOST_DEVICE LinearResizeTaps<T> resize_linear_taps(long o, long in, long out,
                                                       bool align_corners) {
  const T src = resize_source_coord<T>(o, in, out, align_corners);
  long i0 = static_cast<long>(floor(src));  // src >= 0
  if (i0 > in - 1) i0 = in - 1;
  const long i1 = i0 < in - 1 ? i0 + 1 : i0;
  T w1 = src - T(i0);
  w1 = w1 < T(0) ? T(0) : (w1 > T(1) ? T(1) : w1);
  return {i0, i1, T(1) - w1, w1};
}

// The four source taps of output index o along one axis of a bicubic resize (PyTorch
// upsample_bicubic2d, A = -0.75): indices floor(src) - 1 .. floor(src) + 2 clamped to [0, in - 1]
// and their weights. src = o * (in - 1) / (out - 1) with align_corners, else (o + 0.5) / scale -
// 0.5 with scale = the given scale factor when > 0, else out / in; not clamped at 0 (PyTorch's
// cubic source index).
template <class T>
CVD_HOST_DEVICE T cubic_convolution1(T x, T A) {  // |x| <= 1
  return ((A + T(2)) * x - (A + T(3))) * x * x + T(1);
}
template <class T>
CVD_HOST_DEVICE T cubic_convolution2(T x, T A) {  // 1 < |x| < 2
  return ((A * x - T(5) * A) * x + T(8) * A) * x - T(4) * A;
}
template <class T>
struct CubicResizeTaps {
  long i[4];
  T w[4];
};
template <class T>
CVD_HOST_DEVICE CubicResizeTaps<T> resize_cubic_taps(long o, long in, long out, bool align_corners,
                                                     double scale) {
  T src;
  if (align_corners)
    src = out > 1 ? T(o) * T(in - 1) / T(out - 1) : T(0);
  else
    src = (T(o) + T(0.5)) * (scale > 0 ? T(1.0 / scale) : T(in) / T(out)) - T(0.5);
  const T f = floor(src);
  const T t = src - f;
  const T A = T(-0.75);
  CubicResizeTaps<T> taps;
  taps.w[0] = cubic_convolution2<T>(t + T(1), A);
  taps.w[1] = cubic_convolution1<T>(t, A);
  taps.w[2] = cubic_convolution1<T>(T(1) - t, A);
  taps.w[3] = cubic_convolution2<T>(T(2) - t, A);
  const long base = static_cast<long>(f) - 1;
  for (int k = 0; k < 4; ++k) {
    const long idx = base + k;
    taps.i[k] = idx < 0 ? 0 : (idx > in - 1 ? in - 1 : idx);
  }
  return taps;
}

// grid_sample source pixel coordinate of the normalised value g along an axis of `size` pixels
// (PyTorch grid_sampler_compute_source_index), and d(coordinate)/dg in *dcoord. Border padding
// clips to [0, size - 1]; as in PyTorch (clip_coordinates_set_grad) the gradient is 0 at and
// beyond the clip limits (coordinate <= 0 or >= size - 1).
template <class T>
CVD_HOST_DEVICE T grid_source_coord(T g, long size, GridPadding padding, bool align_corners,
                                    T* dcoord) {
  const T c = grid_unnormalize<T>(g, size, align_corners);
  const T d = grid_unnormalize_scale<T>(size, align_corners);
  if (padding != GridPadding::border) {
    *dcoord = d;
    return c;
  }
  const T hi = T(size - 1);
  const bool below = c <= T(0), above = c >= hi;  // selects, no branches: vectorisable
  *dcoord = (below | above) ? T(0) : d;
  return below ? T(0) : (above ? hi : c);
}

}  // namespace cvd
