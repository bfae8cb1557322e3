// Layer norm's math over one row, shared by every backend (the reference loops in double, the
// OpenMP CPU kernels and the CUDA row bodies in float), so the three cannot drift apart. The
// statistics accumulate in double whatever T is; they are rounded to T where they are stored.
#pragma once
#include <cstdint>

#include "engine/elementwise_math.h"  // CVD_HOST_DEVICE

namespace cvd {

// y = (x - mean) * invstd [* gamma] [+ beta] over `cols` values; writes the row's mean and
// 1 / sqrt(variance + eps) (population variance) to *mean and *invstd.
template <class T>
CVD_HOST_DEVICE void layer_norm_row(const T* x, const T* gamma, const T* beta, int64_t cols,
                                    double eps, T* y, T* mean, T* invstd) {
  using std::sqrt;
  double m = 0.0;
  for (int64_t c = 0; c < cols; ++c) m += x[c];
  m /= static_cast<double>(cols);
  double v = 0.0;
  for (int64_t c = 0; c < cols; ++c) v += (x[c] - m) * (x[c] - m);
  v /= static_cast<double>(cols);
  const T mt = static_cast<T>(m), s = static_cast<T>(1.0 / sqrt(v + eps));
  *mean = mt;
  *invstd = s;
  for (int64_t c = 0; c < cols; ++c) {
    T n = (x[c] - mt) * s;
    if (gamma) n *= gamma[c];
    if (beta) n += beta[c];
    y[c] = n;
  }
}

// The input gradient of one row: with n = (x - mean) * invstd and g = gy [* gamma],
// gx = invstd * (g - mean_c(g) - n * mean_c(g * n)).
template <class T>
CVD_HOST_DEVICE void layer_norm_backward_row(const T* gy, const T* x, const T* gamma, T mean,
                                             T invstd, int64_t cols, T* gx) {
  double sum_g = 0.0, sum_gn = 0.0;
  for (int64_t c = 0; c < cols; ++c) {
    const double n = static_cast<double>((x[c] - mean) * invstd);
    const double g = static_cast<double>(gy[c]) * (gamma ? gamma[c] : T(1));
    sum_g += g;
    sum_gn += g * n;
  }
  const double mg = sum_g / static_cast<double>(cols), mgn = sum_gn / static_cast<double>(cols);
  for (int64_t c = 0; c < cols; ++c) {
    const double n = static_cast<double>((x[c] - mean) * invstd);
    const double g = static_cast<double>(gy[c]) * (gamma ? gamma[c] : T(1));
    gx[c] = static_cast<T>(invstd * (g - mg - n * mgn));
  }
}

}  // namespace cvd
