// Reference kernels of the row normalisations over the last dimension, x viewed as [rows, C]:
// layer norm (PyTorch LayerNorm: biased variance, eps inside the square root, optional affine)
// and softmax (the row's maximum subtracted first), forward and backward.
#include <cmath>

#include "engine/kernel_params.h"
#include "engine/row_math.h"
#include "kernels/reference/reference_access.h"
#include "kernels/reference/reference_kernels.h"

namespace cvd::reference {

namespace {

struct Rows {
  int64_t rows, cols;
};

Rows rows_of(const Tensor& x) {
  CVD_ASSERT(is_f64_contiguous(x) && x.dim() >= 1);
  const int64_t cols = x.shape().back();
  return {cols == 0 ? 0 : x.numel() / cols, cols};
}

const double* data_or_null(const Tensor& t) { return t.defined() ? t.data<double>() : nullptr; }

}  // namespace

// in {x [..., C], gamma [C]?, beta [C]?}, out {y, mean [rows], invstd [rows]}; LayerNormParams.
void layer_norm(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 3 && a.out.size() == 3 && a.params != nullptr);
  const Rows g = rows_of(a.in[0]);
  const double* x = a.in[0].data<double>();
  const double *gamma = data_or_null(a.in[1]), *beta = data_or_null(a.in[2]);
  double *y = a.out[0].data<double>(), *mean = a.out[1].data<double>(),
         *invstd = a.out[2].data<double>();
  const double eps = a.p<LayerNormParams>().eps;
  for (int64_t r = 0; r < g.rows; ++r)
    layer_norm_row(x + r * g.cols, gamma, beta, g.cols, eps, y + r * g.cols, mean + r, invstd + r);
}

// in {gy, x, gamma?, mean, invstd}, out {gx?, ggamma?, gbeta?}. gx per row: engine/row_math.h;
// with n = (x - mean) * invstd, ggamma = sum_rows gy * n and gbeta = sum_rows gy.
void layer_norm_backward(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 5 && a.out.size() == 3);
  const Rows g = rows_of(a.in[1]);
  const double *gy = a.in[0].data<double>(), *x = a.in[1].data<double>();
  const double* gamma = data_or_null(a.in[2]);
  const double *mean = a.in[3].data<double>(), *invstd = a.in[4].data<double>();
  double* gx = a.out[0].defined() ? a.out[0].data<double>() : nullptr;
  double* gg = a.out[1].defined() ? a.out[1].data<double>() : nullptr;
  double* gb = a.out[2].defined() ? a.out[2].data<double>() : nullptr;
  for (int64_t c = 0; c < g.cols; ++c) {
    if (gg) gg[c] = 0.0;
    if (gb) gb[c] = 0.0;
  }
  for (int64_t r = 0; r < g.rows; ++r) {
    const double *gyr = gy + r * g.cols, *xr = x + r * g.cols;
    for (int64_t c = 0; c < g.cols; ++c) {
      if (gg) gg[c] += gyr[c] * (xr[c] - mean[r]) * invstd[r];
      if (gb) gb[c] += gyr[c];
    }
    if (gx) layer_norm_backward_row(gyr, xr, gamma, mean[r], invstd[r], g.cols, gx + r * g.cols);
  }
}

// in {x [..., C]}, out {y}: y = exp(x - max) / sum exp(x - max) per row.
void softmax(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1);
  const Rows g = rows_of(a.in[0]);
  const double* x = a.in[0].data<double>();
  double* y = a.out[0].data<double>();
  for (int64_t r = 0; r < g.rows; ++r) {
    const double* xr = x + r * g.cols;
    double* yr = y + r * g.cols;
    double m = xr[0];
    for (int64_t c = 1; c < g.cols; ++c) m = xr[c] > m ? xr[c] : m;
    double s = 0.0;
    for (int64_t c = 0; c < g.cols; ++c) s += (yr[c] = std::exp(xr[c] - m));
    for (int64_t c = 0; c < g.cols; ++c) yr[c] /= s;
  }
}

// in {gy, y}, out {gx}: gx = y * (gy - sum_c gy * y).
void softmax_backward(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 2 && a.out.size() == 1);
  const Rows g = rows_of(a.in[1]);
  const double *gy = a.in[0].data<double>(), *y = a.in[1].data<double>();
  double* gx = a.out[0].data<double>();
  for (int64_t r = 0; r < g.rows; ++r) {
    const double *gyr = gy + r * g.cols, *yr = y + r * g.cols;
    double dot = 0.0;
    for (int64_t c = 0; c < g.cols; ++c) dot += gyr[c] * yr[c];
    for (int64_t c = 0; c < g.cols; ++c) gx[r * g.cols + c] = yr[c] * (gyr[c] - dot);
  }
}

}  // namespace cvd::reference
