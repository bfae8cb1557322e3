// CUDA kernel bodies and op drivers of the row normalisations over the last dimension (x as
// [rows, C]): layer norm and softmax, forward and backward, the math of kernels/reference/
// reference_rows.cpp. One thread per row (statistics and dot products in double); layer norm's
// gamma / beta gradients are gathers, one thread per column summing over the rows, so nothing
// needs atomics and every result is deterministic. Rows of a few hundred values (a ViT's width)
// keep each thread short; a block-per-row reduction is future work if a profile asks for it.
#pragma once
#include <cmath>

#include "engine/dispatch.h"
#include "engine/kernel_params.h"
#include "engine/row_math.h"
#include "kernels/cuda/launch_body.h"

namespace cvd::cuda {

struct RowGeometry {
  int64_t rows, cols;
};

inline RowGeometry row_geometry(const Tensor& x) {
  const int64_t cols = x.shape().back();
  return {cols == 0 ? 0 : x.numel() / cols, cols};
}

template <class T>
struct LayerNormBody {
  const T *x, *gamma, *beta;
  T *y, *mean, *invstd;
  RowGeometry g;
  double eps;
  CVD_HOST_DEVICE void operator()(int64_t r) const {
    layer_norm_row(x + r * g.cols, gamma, beta, g.cols, eps, y + r * g.cols, mean + r, invstd + r);
  }
};

// gx of one row (engine/row_math.h).
template <class T>
struct LayerNormBackwardRowBody {
  const T *gy, *x, *gamma, *mean, *invstd;
  T* gx;
  RowGeometry g;
  CVD_HOST_DEVICE void operator()(int64_t r) const {
    layer_norm_backward_row(gy + r * g.cols, x + r * g.cols, gamma, mean[r], invstd[r], g.cols,
                            gx + r * g.cols);
  }
};

// ggamma[c] = sum_rows gy * n, gbeta[c] = sum_rows gy: one thread per column.
template <class T>
struct LayerNormBackwardColumnBody {
  const T *gy, *x, *mean, *invstd;
  T *ggamma, *gbeta;
  RowGeometry g;
  CVD_HOST_DEVICE void operator()(int64_t c) const {
    double sg = 0.0, sb = 0.0;
    for (int64_t r = 0; r < g.rows; ++r) {
      const T v = gy[r * g.cols + c];
      sg += static_cast<double>(v) * static_cast<double>((x[r * g.cols + c] - mean[r]) * invstd[r]);
      sb += v;
    }
    if (ggamma) ggamma[c] = static_cast<T>(sg);
    if (gbeta) gbeta[c] = static_cast<T>(sb);
  }
};

template <class T>
struct SoftmaxBody {
  const T* x;
  T* y;
  RowGeometry g;
  CVD_HOST_DEVICE void operator()(int64_t r) const {
    using std::exp;
    const T* xr = x + r * g.cols;
    T* yr = y + r * g.cols;
    T m = xr[0];
    for (int64_t c = 1; c < g.cols; ++c) m = xr[c] > m ? xr[c] : m;
    double s = 0.0;
    for (int64_t c = 0; c < g.cols; ++c) {
      yr[c] = exp(xr[c] - m);
      s += yr[c];
    }
    const T inv = static_cast<T>(1.0 / s);
    for (int64_t c = 0; c < g.cols; ++c) yr[c] *= inv;
  }
};

template <class T>
struct SoftmaxBackwardBody {
  const T *gy, *y;
  T* gx;
  RowGeometry g;
  CVD_HOST_DEVICE void operator()(int64_t r) const {
    const T *gyr = gy + r * g.cols, *yr = y + r * g.cols;
    double dot = 0.0;
    for (int64_t c = 0; c < g.cols; ++c) dot += static_cast<double>(gyr[c]) * yr[c];
    const T d = static_cast<T>(dot);
    for (int64_t c = 0; c < g.cols; ++c) gx[r * g.cols + c] = yr[c] * (gyr[c] - d);
  }
};

// ---- Op drivers ---------------------------------------------------------------------------------

template <class Launch>
void layer_norm_op(const KernelArgs& a) {
  const Tensor& x = a.in[0];
  const RowGeometry g = row_geometry(x);
  Launch::launch(g.rows, LayerNormBody<float>{x.data<float>(), data_or_null<float>(a.in[1]),
                                              data_or_null<float>(a.in[2]), a.out[0].data<float>(),
                                              a.out[1].data<float>(), a.out[2].data<float>(), g,
                                              a.p<LayerNormParams>().eps});
}

template <class Launch>
void layer_norm_backward_op(const KernelArgs& a) {
  const Tensor &gy = a.in[0], &x = a.in[1];
  const RowGeometry g = row_geometry(x);
  if (a.out[0].defined())
    Launch::launch(
        g.rows, LayerNormBackwardRowBody<float>{gy.data<float>(), x.data<float>(),
                                                data_or_null<float>(a.in[2]), a.in[3].data<float>(),
                                                a.in[4].data<float>(), a.out[0].data<float>(), g});
  if (a.out[1].defined() || a.out[2].defined())
    Launch::launch(
        g.cols, LayerNormBackwardColumnBody<float>{
                    gy.data<float>(), x.data<float>(), a.in[3].data<float>(), a.in[4].data<float>(),
                    data_or_null<float>(a.out[1]), data_or_null<float>(a.out[2]), g});
}

template <class Launch>
void softmax_op(const KernelArgs& a) {
  const RowGeometry g = row_geometry(a.in[0]);
  Launch::launch(g.rows, SoftmaxBody<float>{a.in[0].data<float>(), a.out[0].data<float>(), g});
}

template <class Launch>
void softmax_backward_op(const KernelArgs& a) {
  const RowGeometry g = row_geometry(a.in[1]);
  Launch::launch(g.rows, SoftmaxBackwardBody<float>{a.in[0].data<float>(), a.in[1].data<float>(),
                                                    a.out[0].data<float>(), g});
}

}  // namespace cvd::cuda
