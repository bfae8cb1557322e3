// Reference kernels of the row normalisations over the last dimension, x viewed as [rows, C]:
// layer norm (PyTorch LayerNorm: biased variance, eps inside the square root, optional affine)
// and softmax (the row's maximum subtracted first), forward and backward.
#include <cmath>

#include "engine/kernel_params.h"
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
  for (int64_t r = 0; r < g.rows; ++r) {
    const double* xr = x + r * g.cols;
    double m = 0.0;
    for (int64_t c = 0; c < g.cols; ++c) m += xr[c];
    m /= static_cast<double>(g.cols);
    double v = 0.0;
    for (int64_t c = 0; c < g.cols; ++c) v += (xr[c] - m) * (xr[c] - m);
    v /= static_cast<double>(g.cols);
    const double s = 1.0 / std::sqrt(v + eps);
    mean[r] = m;
    invstd[r] = s;
    for (int64_t c = 0; c < g.cols; ++c) {
      double n = (xr[c] - m) * s;
      if (gamma) n *= gamma[c];
      if (beta) n += beta[c];
      y[r * g.cols + c] = n;
    }
  }
}

// in {gy, x, gamma?, mean, invstd}, out {gx?, ggamma?, gbeta?}. With n = (x - mean) * invstd and
// g = gy * gamma: gx = invstd * (g - mean_c(g) - n * mean_c(g * n)); ggamma = sum_rows gy * n;
// gbeta = sum_rows gy.
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
    double sum_g = 0.0, sum_gn = 0.0;
    for (int64_t c = 0; c < g.cols; ++c) {
      const double n = (xr[c] - mean[r]) * invstd[r];
      const double gc = gyr[c] * (gamma ? gamma[c] : 1.0);
      sum_g += gc;
      sum_gn += gc * n;
      if (gg) gg[c] += gyr[c] * n;
      if (gb) gb[c] += gyr[c];
    }
    if (!gx) continue;
    const double inv_c = 1.0 / static_cast<double>(g.cols);
    for (int64_t c = 0; c < g.cols; ++c) {
      const double n = (xr[c] - mean[r]) * invstd[r];
      const double gc = gyr[c] * (gamma ? gamma[c] : 1.0);
      gx[r * g.cols + c] = invstd[r] * (gc - sum_g * inv_c - n * sum_gn * inv_c);
    }
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
