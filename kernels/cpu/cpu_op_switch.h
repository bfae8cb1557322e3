// Turns the runtime op enums of UnaryParams / BinaryParams into compile-time template arguments,
// so the element loops of the OpenMP kernels inline one case of the shared math and vectorise.
// Usage: with_unary_op(op, [&]<UnaryOp OP>() { ... });
#pragma once
#include "engine/kernel_params.h"

namespace cvd::cpu {

template <class F>
void with_unary_op(UnaryOp op, F&& f) {
  switch (op) {
#define CVD_CASE(name, cost) \
  case UnaryOp::name:        \
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
    CVD_BINARY_OPS(CVD_CASE)
#undef CVD_CASE
  }
}

}  // namespace cvd::cpu
