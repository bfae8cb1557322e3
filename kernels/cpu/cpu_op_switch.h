// Turns the runtime op enums of UnaryParams / BinaryParams into compile-time template arguments,
// so the element loops of the OpenMP kernels inline one case of the shared math and vectorise.
// Usage: with_unary_op(op, [&]<UnaryOp OP>() { ... });
#pragma once
#include "engine/kernel_params.h"

namespace cvd::cpu {

template <class F>
void with_unary_op(UnaryOp op, F&& f) {
  switch (op) {
#define CVD_CASE(name) \
  case UnaryOp::name:  \
    return f.template operator()<UnaryOp::name>();
    CVD_UNARY_OPS(CVD_CASE)
#undef CVD_CASE
  }
}

template <class F>
void with_binary_op(BinaryOp op, F&& f) {
  switch (op) {
#define CVD_CASE(name) \
  case BinaryOp::name: \
    return f.template operator()<BinaryOp::name>();
    CVD_CASE(add)
    CVD_CASE(sub)
    CVD_CASE(mul)
    CVD_CASE(div)
    CVD_CASE(minimum)
    CVD_CASE(maximum)
    CVD_CASE(gt)
    CVD_CASE(ge)
    CVD_CASE(lt)
    CVD_CASE(le)
    CVD_CASE(eq)
#undef CVD_CASE
  }
}

// Relative cost of one element of a unary op (transcendentals are ~20x a max or an add).
inline int64_t unary_cost(UnaryOp op) {
  switch (op) {
    case UnaryOp::sigmoid:
    case UnaryOp::tanh:
    case UnaryOp::exp:
    case UnaryOp::log:
    case UnaryOp::pow_scalar:
    case UnaryOp::gelu:
      return 20;
    case UnaryOp::sqrt:
    case UnaryOp::reciprocal:
      return 4;
    default:
      return 1;
  }
}

}  // namespace cvd::cpu
