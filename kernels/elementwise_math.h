// Element-wise math shared by every backend: the reference loops, the OpenMP CPU kernels and
// the CUDA kernels all call these functions, so their logic is tested on the CPU.
#pragma once
#include <cmath>

#include "kernels/kernel_params.h"

#if defined(__CUDACC__)
#define CVD_HOST_DEVICE __host__ __device__ __forceinline__
#else
#define CVD_HOST_DEVICE inline
#endif

namespace cvd {

template <class T>
CVD_HOST_DEVICE T unary_forward(UnaryOp op, T x, T a, T b) {
  switch (op) {
    case UnaryOp::relu: return x > T(0) ? x : T(0);
    case UnaryOp::clip: return x < a ? a : (x > b ? b : x);
    case UnaryOp::leaky_relu: return x > T(0) ? x : a * x;
    case UnaryOp::sigmoid: return T(1) / (T(1) + exp(-x));
    case UnaryOp::tanh: return tanh(x);
    case UnaryOp::exp: return exp(x);
    case UnaryOp::log: return log(x);
    case UnaryOp::abs: return x < T(0) ? -x : x;
    case UnaryOp::sqrt: return sqrt(x);
    case UnaryOp::neg: return -x;
    case UnaryOp::reciprocal: return T(1) / x;
    case UnaryOp::pow_scalar: return pow(x, a);
    case UnaryOp::mul_scalar: return x * a;
    case UnaryOp::add_scalar: return x + a;
  }
  return x;
}

// d(unary)/dx times gy, from the input x and the output y.
template <class T>
CVD_HOST_DEVICE T unary_backward(UnaryOp op, T gy, T x, T y, T a, T b) {
  switch (op) {
    case UnaryOp::relu: return x > T(0) ? gy : T(0);
    case UnaryOp::clip: return (x > a && x < b) ? gy : T(0);
    case UnaryOp::leaky_relu: return x > T(0) ? gy : a * gy;
    case UnaryOp::sigmoid: return gy * y * (T(1) - y);
    case UnaryOp::tanh: return gy * (T(1) - y * y);
    case UnaryOp::exp: return gy * y;
    case UnaryOp::log: return gy / x;
    case UnaryOp::abs: return x > T(0) ? gy : (x < T(0) ? -gy : T(0));
    case UnaryOp::sqrt: return gy * T(0.5) / y;
    case UnaryOp::neg: return -gy;
    case UnaryOp::reciprocal: return -gy * y * y;
    case UnaryOp::pow_scalar: return gy * a * pow(x, a - T(1));
    case UnaryOp::mul_scalar: return gy * a;
    case UnaryOp::add_scalar: return gy;
  }
  return gy;
}

template <class T>
CVD_HOST_DEVICE T binary_forward(BinaryOp op, T x, T y) {
  switch (op) {
    case BinaryOp::add: return x + y;
    case BinaryOp::sub: return x - y;
    case BinaryOp::mul: return x * y;
    case BinaryOp::div: return x / y;
    case BinaryOp::minimum: return y < x ? y : x;
    case BinaryOp::maximum: return y > x ? y : x;
    case BinaryOp::gt: return x > y ? T(1) : T(0);
    case BinaryOp::ge: return x >= y ? T(1) : T(0);
    case BinaryOp::lt: return x < y ? T(1) : T(0);
    case BinaryOp::le: return x <= y ? T(1) : T(0);
    case BinaryOp::eq: return x == y ? T(1) : T(0);
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

}  // namespace cvd
