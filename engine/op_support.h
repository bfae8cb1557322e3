// Internal helpers of the op implementations in engine/ops_*.cpp (not part of the API).
#pragma once
#include "engine/autograd.h"
#include "engine/dispatch.h"
#include "engine/ops.h"

namespace cvd::detail {

inline void check_same_kind(const char* op, const Tensor& a, const Tensor& b) {
  if (!b.defined()) return;
  CVD_CHECK(a.dtype() == b.dtype(), "{}: dtype mismatch ({} vs {})", op, a.str(), b.str());
  CVD_CHECK(a.device() == b.device(), "{}: device mismatch ({} vs {})", op, a.str(), b.str());
}

inline Tensor empty_like_kind(const Shape& shape, const Tensor& like) {
  return Tensor::empty(shape, like.dtype(), like.device());
}

inline Tensor contiguous_or_undefined(const Tensor& t) { return t.defined() ? t.contiguous() : t; }

// A view of `x` with the given geometry, sharing storage, without autograd history.
Tensor make_view(const Tensor& x, const Shape& shape, const Shape& strides, int64_t offset);

}  // namespace cvd::detail
