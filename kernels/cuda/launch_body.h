// What every CUDA kernel body in kernels/cuda/*_body.h is built from. A body is a small
// trivially-copyable functor whose CVD_HOST_DEVICE operator()(int64_t i) computes the work of
// flat thread index i in [0, n). The CUDA backend runs it with one thread per index
// (DeviceLaunch, kernels/cuda/device_launch.cuh); tests run the very same body on the CPU with
// EmulatedLaunch, a loop over all indices. Op drivers (`template <class Launch> void op(args)`)
// are plain C++ too, so an emulated run exercises the whole kernel, argument packing included.
#pragma once
#include <cstdint>

#include "engine/elementwise_math.h"
#include "engine/error.h"
#include "engine/tensor.h"

namespace cvd::cuda {

inline constexpr int kMaxDims = 8;

// Shape and element strides of a tensor view (up to kMaxDims dims), passed by value to kernels.
struct ViewGeometry {
  int ndim = 0;
  int64_t size[kMaxDims] = {};
  int64_t stride[kMaxDims] = {};
  // Element offset of the element whose row-major index over `size` is `linear`.
  CVD_HOST_DEVICE int64_t offset(int64_t linear) const {
    int64_t off = 0;
    for (int d = ndim - 1; d >= 0; --d) {
      off += (linear % size[d]) * stride[d];
      linear /= size[d];
    }
    return off;
  }
};

inline ViewGeometry view_geometry(const Tensor& t) {
  CVD_CHECK(t.dim() <= kMaxDims, "CUDA kernels support at most {} dims, got {}", kMaxDims, t.str());
  ViewGeometry g;
  g.ndim = t.dim();
  for (int d = 0; d < t.dim(); ++d) {
    g.size[d] = t.shape()[d];
    g.stride[d] = t.strides()[d];
  }
  return g;
}

// *p += v, atomically on the device (several threads may hit the same address); a plain add in
// an emulated launch, which runs the indices one after another.
template <class T>
CVD_HOST_DEVICE void atomic_add(T* p, T v) {
#if defined(__CUDA_ARCH__)
  atomicAdd(p, v);
#else
  *p += v;
#endif
}

// Runs body(i) for every i in [0, n) on the calling CPU thread: the CPU stand-in for a kernel
// launch with one thread per index, used by tests/test_cuda_emulated.cpp.
struct EmulatedLaunch {
  template <class Body>
  static void launch(int64_t n, const Body& body) {
    for (int64_t i = 0; i < n; ++i) body(i);
  }
};

// Typed pointer to a tensor's data (nullptr for an undefined tensor).
template <class T>
T* data_or_null(const Tensor& t) {
  return t.defined() ? t.data<T>() : nullptr;
}

}  // namespace cvd::cuda
