// The element-wise ops, defined once: their names, parameters and math, shared by every backend
// (the reference loops, the OpenMP CPU kernels and the CUDA kernels all call these functions, so
// their logic is tested on the CPU). A new unary op is one X(...) line and its cases below, its
// public function in engine/ops.h and its line in tests/op_case_table.cpp.
#pragma once
#include <cmath>
#include <cstdint>

#if defined(__CUDACC__)
#define CVD_HOST_DEVICE __host__ __device__ __forceinline__
#else
#define CVD_HOST_DEVICE inline
#endif

namespace cvd {

// The unary ops, one X(name, cost) each; the enum, op names and the CPU kernels' compile-time
// switch are generated from this list. cost: relative cost of one element (a transcendental is
// ~20x a max or an add), which sizes the CPU kernels' parallel chunks.
//   relu        max(x, 0)
//   clip        min(max(x, a), b) (relu6 = clip 0..6); gradient 1 strictly inside (a, b)
//   leaky_relu  x > 0 ? x : a * x
//   sigmoid, tanh, exp, log, sqrt, neg, reciprocal
//   abs         gradient sign(x), 0 at 0
//   pow_scalar  x ^ a
//   mul_scalar  x * a
//   add_scalar  x + a
//   gelu        0.5 x (1 + erf(x / sqrt 2)) (PyTorch's default GELU); gradient Phi(x) + x phi(x)
//   softplus    log(1 + e^x), x itself above 20 (PyTorch's threshold); gradient sigmoid(x)
// clang-format off
#define CVD_UNARY_OPS(X) \
  X(relu, 1)         \
  X(clip, 1)         \
  X(leaky_relu, 1)   \
  X(sigmoid, 20)     \
  X(tanh, 20)        \
  X(exp, 20)         \
  X(log, 20)         \
  X(abs, 1)          \
  X(sqrt, 4)         \
  X(neg, 1)          \
  X(reciprocal, 4)   \
  X(pow_scalar, 20)  \
  X(mul_scalar, 1)   \
  X(add_scalar, 1)   \
  X(gelu, 20)         \
  X(softplus, 20)
// clang-format on
enum class UnaryOp : int {
#define CVD_X(name, cost) name,
  CVD_UNARY_OPS(CVD_X)
#undef CVD_X
};
struct UnaryParams {
  UnaryOp op = UnaryOp::relu;
  double a = 0.0;
  double b = 0.0;
};
CVD_HOST_DEVICE int64_t unary_cost(UnaryOp op) {
  switch (op) {
#define CVD_X(name, cost) \
  case UnaryOp::name:     \
    return cost;
    CVD_UNARY_OPS(CVD_X)
#undef CVD_X
  }
  return 1;
}

// The binary ops (broadcasting); the comparisons gt..eq produce 1 or 0 and are not
// differentiable.
#define CVD_BINARY_OPS(X) \
  X(add) X(sub) X(mul) X(div) X(minimum) X(maximum) X(gt) X(ge) X(lt) X(le) X(eq)
enum class BinaryOp : int {
#define CVD_X(name) name,
  CVD_BINARY_OPS(CVD_X)
#undef CVD_X
};
struct BinaryParams {
  BinaryOp op = BinaryOp::add;
};

template <class T>
CVD_HOST_DEVICE T unary_forward(UnaryOp op, T x, T a, T b) {
  using std::erf, std::exp, std::log, std::log1p, std::pow, std::sqrt,
      std::tanh;  // float overloads
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
    case UnaryOp::softplus:
      return x > T(20) ? x : log1p(exp(x));
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
    case UnaryOp::softplus:
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
    case UnaryOp::softplus:
      return x > T(20) ? gy : gy / (T(1) + exp(-x));
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
