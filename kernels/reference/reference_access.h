// Element access shared by the reference kernels: precondition checks on kernel arguments, and
// addressing of strided views (the inputs of copy, binary and where may have any strides).
#pragma once
#include <cstdint>

#include "engine/tensor.h"

namespace cvd::reference {

// A defined CPU tensor of dtype f64 laid out contiguously (what every reference kernel reads and
// writes, except the strided inputs of copy / binary / where).
inline bool is_f64_contiguous(const Tensor& t) {
  return t.defined() && t.device().is_cpu() && t.dtype() == DType::f64 && t.is_contiguous();
}

// Element offset, relative to t.data_ptr(), of the element whose row-major index over t's shape
// is `linear`. Works for any strides, including 0 (broadcast) strides.
inline int64_t strided_offset(const Tensor& t, int64_t linear) {
  int64_t offset = 0;
  for (int d = t.dim() - 1; d >= 0; --d) {
    const int64_t size = t.shape()[d];
    offset += (linear % size) * t.strides()[d];
    linear /= size;
  }
  return offset;
}

// Reads the element at `offset` (see strided_offset) of an f32 or f64 CPU tensor as double.
inline double load_as_double(const Tensor& t, int64_t offset) {
  if (t.dtype() == DType::f64) return static_cast<const double*>(t.data_ptr())[offset];
  return static_cast<double>(static_cast<const float*>(t.data_ptr())[offset]);
}

// Writes `v` converted to t's dtype at element `offset` of an f32 or f64 CPU tensor.
inline void store_from_double(const Tensor& t, int64_t offset, double v) {
  if (t.dtype() == DType::f64) {
    static_cast<double*>(t.data_ptr())[offset] = v;
  } else {
    static_cast<float*>(t.data_ptr())[offset] = static_cast<float>(v);
  }
}

// Product of shape[begin, end).
inline int64_t dims_product(const Shape& shape, int begin, int end) {
  int64_t p = 1;
  for (int d = begin; d < end; ++d) p *= shape[d];
  return p;
}

}  // namespace cvd::reference
