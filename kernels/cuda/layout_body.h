// CUDA kernel bodies and op drivers of the layout ops: reduce_sum, concat, pad.
// reduce_sum is a gather: one thread per output element sums its reduced elements (accumulating
// in double), so no atomics or shared-memory tree is needed; long reductions to few outputs are
// split into chunks summed in a second pass (two launches instead of a shared-memory tree).
#pragma once
#include <vector>

#include "engine/dispatch.h"
#include "engine/kernel_params.h"
#include "kernels/cuda/launch_body.h"

namespace cvd::cuda {

// y[j] = sum over r of x[kept.offset(j) + reduced.offset(r)].
template <class T>
struct ReduceSumBody {
  const T* x;
  T* y;
  ViewGeometry kept, reduced;
  int64_t reduced_count;
  CVD_HOST_DEVICE void operator()(int64_t j) const {
    const T* base = x + kept.offset(j);
    double acc = 0.0;
    for (int64_t r = 0; r < reduced_count; ++r) acc += static_cast<double>(base[reduced.offset(r)]);
    y[j] = static_cast<T>(acc);
  }
};

// Two-pass form for long reductions: pass 1 sums chunk c of output j's reduced elements into
// partial[j * chunks + c] (double); pass 2 (PartialSumBody) adds each output's chunks.
template <class T>
struct ReduceSumChunkBody {
  const T* x;
  double* partial;
  ViewGeometry kept, reduced;
  int64_t reduced_count, chunk, chunks;
  CVD_HOST_DEVICE void operator()(int64_t t) const {
    const int64_t j = t / chunks, c = t % chunks;
    const T* base = x + kept.offset(j);
    const int64_t end = (c + 1) * chunk < reduced_count ? (c + 1) * chunk : reduced_count;
    double acc = 0.0;
    for (int64_t r = c * chunk; r < end; ++r) acc += static_cast<double>(base[reduced.offset(r)]);
    partial[t] = acc;
  }
};

template <class T>
struct PartialSumBody {
  const double* partial;
  T* y;
  int64_t chunks;
  CVD_HOST_DEVICE void operator()(int64_t j) const {
    double acc = 0.0;
    for (int64_t c = 0; c < chunks; ++c) acc += partial[j * chunks + c];
    y[j] = static_cast<T>(acc);
  }
};

// Copies x [outer, x_len, inner] into y [outer, y_len, inner] at position `start` along dim 1.
template <class T>
struct ConcatSlabBody {
  const T* x;
  T* y;
  int64_t x_len, y_len, inner, start;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    const int64_t in = i % inner;
    const int64_t k = (i / inner) % x_len;
    const int64_t o = i / (inner * x_len);
    y[(o * y_len + start + k) * inner + in] = x[i];
  }
};

// y[j] = x[index - before] inside, `value` in the padding; shapes as ViewGeometry (contiguous).
template <class T>
struct PadBody {
  const T* x;
  T* y;
  ViewGeometry x_view;  // x sizes and strides
  int64_t y_size[kMaxDims];
  int64_t before[kMaxDims];
  int ndim;
  T value;
  CVD_HOST_DEVICE void operator()(int64_t j) const {
    int64_t rest = j, off = 0;
    for (int d = ndim - 1; d >= 0; --d) {
      const int64_t xi = rest % y_size[d] - before[d];
      rest /= y_size[d];
      if (xi < 0 || xi >= x_view.size[d]) {
        y[j] = value;
        return;
      }
      off += xi * x_view.stride[d];
    }
    y[j] = x[off];
  }
};

template <class Launch>
void reduce_sum_op(const KernelArgs& a) {
  const Tensor &x = a.in[0], &y = a.out[0];
  const std::vector<int>& dims = a.p<ReduceParams>().dims;
  CVD_CHECK(x.dim() <= kMaxDims, "CUDA reduce_sum supports at most {} dims, got {}", kMaxDims,
            x.str());
  ViewGeometry kept, reduced;
  int64_t reduced_count = 1;
  for (int d = 0; d < x.dim(); ++d) {
    bool is_reduced = false;
    for (int r : dims) is_reduced = is_reduced || r == d;
    ViewGeometry& g = is_reduced ? reduced : kept;
    g.size[g.ndim] = x.shape()[d];
    g.stride[g.ndim] = x.strides()[d];
    ++g.ndim;
    if (is_reduced) reduced_count *= x.shape()[d];
  }
  // Few outputs with long reductions: split each into chunks so that enough threads work.
  constexpr int64_t kChunk = 4096;
  if (reduced_count > 2 * kChunk && y.numel() < 65536) {
    const int64_t chunks = (reduced_count + kChunk - 1) / kChunk;
    const Tensor partial = Tensor::empty({y.numel() * chunks}, DType::f64, y.device());
    Launch::launch(y.numel() * chunks,
                   ReduceSumChunkBody<float>{x.data<float>(), partial.data<double>(), kept, reduced,
                                             reduced_count, kChunk, chunks});
    Launch::launch(y.numel(),
                   PartialSumBody<float>{partial.data<double>(), y.data<float>(), chunks});
    return;
  }
  Launch::launch(y.numel(), ReduceSumBody<float>{x.data<float>(), y.data<float>(), kept, reduced,
                                                 reduced_count});
}

template <class Launch>
void concat_op(const KernelArgs& a) {
  const Tensor& y = a.out[0];
  const int dim = a.p<ConcatParams>().dim;
  int64_t inner = 1;
  for (int d = dim + 1; d < y.dim(); ++d) inner *= y.shape()[d];
  int64_t start = 0;
  for (const Tensor& x : a.in) {
    const int64_t x_len = x.shape()[dim];
    if (x.numel() > 0) {
      Launch::launch(x.numel(), ConcatSlabBody<float>{x.data<float>(), y.data<float>(), x_len,
                                                      y.shape()[dim], inner, start});
    }
    start += x_len;
  }
}

template <class Launch>
void pad_op(const KernelArgs& a) {
  const Tensor &x = a.in[0], &y = a.out[0];
  const PadParams& p = a.p<PadParams>();
  PadBody<float> body{x.data<float>(),
                      y.data<float>(),
                      view_geometry(x),
                      {},
                      {},
                      x.dim(),
                      static_cast<float>(p.value)};
  for (int d = 0; d < x.dim(); ++d) {
    body.y_size[d] = y.shape()[d];
    body.before[d] = p.before[d];
  }
  Launch::launch(y.numel(), body);
}

}  // namespace cvd::cuda
