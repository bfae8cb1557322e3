// Element-wise math shared by every backend: the reference loops, the OpenMP CPU kernels and
// the CUDA kernels all call these functions, so their logic is tested on the CPU.
#pragma once
#include <cmath>

#include "engine/kernel_params.h"

#if defined(__CUDACC__)
#define CVD_HOST_DEVICE __host__ __device__ __forceinline__
#else
#define CVD_HOST_DEVICE inline
#endif

namespace cvd {

template <class T>
CVD_HOST_DEVICE T unary_forward(UnaryOp op, T x, T a, T b) {
  using std::erf, std::exp, std::log, std::pow, std::sqrt, std::tanh;  // float overloads
  switch (op) {
    case UnaryOp::relu:
      return x > T(0) ? x : T(0);
    case UnaryOp::clip:
      return x < a ? a : (x > b ? b : x);
    case UnaryOp::leaky_relu:
      return x > T(0) ? x : a * x;
    case UnaryOp::sigmoid:
      return T(1) / (T(1) + exp(-x));
    case UnaryOp::tanh:
      return tanh(x);
    case UnaryOp::exp:
      return exp(x);
    case UnaryOp::log:
      return log(x);
    case UnaryOp::abs:
      return x < T(0) ? -x : x;
    case UnaryOp::sqrt:
      return sqrt(x);
    case UnaryOp::neg:
      return -x;
    case UnaryOp::reciprocal:
      return T(1) / x;
    case UnaryOp::pow_scalar:
      return pow(x, a);
    case UnaryOp::mul_scalar:
      return x * a;
    case UnaryOp::add_scalar:
      return x + a;
    case UnaryOp::gelu:
      return T(0.5) * x * (T(1) + erf(x * T(0.70710678118654752440)));
  }
  return x;
}

// Which operands unary_backward reads for `op`: the input x, the output y, or neither (callers
// may then pass any tensor of the right shape, e.g. gy, in place of the other). relu and clip
// read y: y > 0 exactly where x > 0, and a < y < b exactly where a < x < b.
struct UnaryOperands {
  bool x = false, y = false;
};
CVD_HOST_DEVICE UnaryOperands unary_backward_reads(UnaryOp op) {
  switch (op) {
    case UnaryOp::leaky_relu:
    case UnaryOp::log:
    case UnaryOp::abs:
    case UnaryOp::pow_scalar:
    case UnaryOp::gelu:
      return {true, false};
    case UnaryOp::relu:
    case UnaryOp::clip:
    case UnaryOp::sigmoid:
    case UnaryOp::tanh:
    case UnaryOp::exp:
    case UnaryOp::sqrt:
    case UnaryOp::reciprocal:
      return {false, true};
    case UnaryOp::neg:
    case UnaryOp::mul_scalar:
    case UnaryOp::add_scalar:
      return {false, false};
  }
  return {true, true};
}

// d(unary)/dx times gy, from the input x and the output y (only those unary_backward_reads
// names are read).
template <class T>
CVD_HOST_DEVICE T unary_backward(UnaryOp op, T gy, T x, T y, T a, T b) {
  using std::erf, std::exp, std::pow;
  switch (op) {
    case UnaryOp::relu:
      return y > T(0) ? gy : T(0);
    case UnaryOp::clip:
      return (y > a && y < b) ? gy : T(0);
    case UnaryOp::leaky_relu:
      return x > T(0) ? gy : a * gy;
    case UnaryOp::sigmoid:
      return gy * y * (T(1) - y);
    case UnaryOp::tanh:
      return gy * (T(1) - y * y);
    case UnaryOp::exp:
      return gy * y;
    case UnaryOp::log:
      return gy / x;
    case UnaryOp::abs:
      return x > T(0) ? gy : (x < T(0) ? -gy : T(0));
    case UnaryOp::sqrt:
      return gy * T(0.5) / y;
    case UnaryOp::neg:
      return -gy;
    case UnaryOp::reciprocal:
      return -gy * y * y;
    case UnaryOp::pow_scalar:
      return gy * a * pow(x, a - T(1));
    case UnaryOp::mul_scalar:
      return gy * a;
    case UnaryOp::add_scalar:
      return gy;
    case UnaryOp::gelu:  // Phi(x) + x phi(x)
      return gy * (T(0.5) * (T(1) + erf(x * T(0.70710678118654752440))) +
                   x * T(0.39894228040143267794) * exp(T(-0.5) * x * x));
  }
  return gy;
}

template <class T>
CVD_HOST_DEVICE T binary_forward(BinaryOp op, T x, T y) {
  switch (op) {
    case BinaryOp::add:
      return x + y;
    case BinaryOp::sub:
      return x - y;
    case BinaryOp::mul:
      return x * y;
    case BinaryOp::div:
      return x / y;
    case BinaryOp::minimum:
      return y < x ? y : x;
    case BinaryOp::maximum:
      return y > x ? y : x;
    case BinaryOp::gt:
      return x > y ? T(1) : T(0);
    case BinaryOp::ge:
      return x >= y ? T(1) : T(0);
    case BinaryOp::lt:
      return x < y ? T(1) : T(0);
    case BinaryOp::le:
      return x <= y ? T(1) : T(0);
    case BinaryOp::eq:
      return x == y ? T(1) : T(0);
  }
  return x;
}

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

// ---- Optimiser steps, one element (PyTorch torch.optim semantics, see kernel_params.h) ---------

// Adam. step_size = lr / (1 - beta1^t), bc2_sqrt = sqrt(1 - beta2^t), computed once per step.
template <class T>
CVD_HOST_DEVICE void adam_update_element(T& p, T g, T& m, T& v, T beta1, T beta2, T eps,
                                         T weight_decay, T step_size, T bc2_sqrt) {
  if (weight_decay != T(0)) g = g + weight_decay * p;
  m = m * beta1 + (T(1) - beta1) * g;
  v = v * beta2 + (T(1) - beta2) * g * g;
  const T denom = sqrt(v) / bc2_sqrt + eps;
  p = p - step_size * (m / denom);
}

// SGD with momentum (buf unused when momentum == 0).
template <class T>
CVD_HOST_DEVICE void sgd_update_element(T& p, T g, T& buf, T lr, T momentum, T dampening,
                                        T weight_decay, bool nesterov, bool first_step) {
  if (weight_decay != T(0)) g = g + weight_decay * p;
  if (momentum != T(0)) {
    buf = first_step ? g : buf * momentum + (T(1) - dampening) * g;
    g = nesterov ? g + momentum * buf : buf;
  }
  p = p - lr * g;
}

}  // namespace cvd
