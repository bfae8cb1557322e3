// OpenMP f32 kernels of the row normalisations over the last dimension (x as [rows, C]): layer
// norm and softmax, forward and backward. Parallel over rows; each row's statistics and dot
// products accumulate in double. Layer norm's gamma / beta gradients sum over rows: per-thread
// partial sums (double), added in thread order, so the result does not depend on timing.
#include <algorithm>
#include <cmath>
#include <vector>

#include "engine/dispatch.h"
#include "engine/error.h"
#include "engine/kernel_params.h"
#include "engine/row_math.h"
#include "kernels/cpu/cpu_openmp_families.h"
#include "kernels/cpu/cpu_parallel.h"

namespace cvd::cpu {

namespace {

struct Rows {
  int64_t rows, cols;
};

Rows rows_of(const Tensor& x) {
  CVD_ASSERT(x.defined() && x.device().is_cpu() && x.dtype() == DType::f32 && x.is_contiguous());
  const int64_t cols = x.shape().back();
  return {cols == 0 ? 0 : x.numel() / cols, cols};
}

const float* data_or_null(const Tensor& t) { return t.defined() ? t.data<float>() : nullptr; }
float* out_or_null(const Tensor& t) { return t.defined() ? t.data<float>() : nullptr; }

// in {x, gamma?, beta?}, out {y, mean, invstd}; LayerNormParams.
void layer_norm(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 3 && a.out.size() == 3 && a.params != nullptr);
  const Rows g = rows_of(a.in[0]);
  const float* x = a.in[0].data<float>();
  const float *gamma = data_or_null(a.in[1]), *beta = data_or_null(a.in[2]);
  float *y = a.out[0].data<float>(), *mean = a.out[1].data<float>(),
        *invstd = a.out[2].data<float>();
  const double eps = a.p<LayerNormParams>().eps;
  parallel_ranges(g.rows, 4 * g.cols, [&](int64_t b, int64_t e) {
    for (int64_t r = b; r < e; ++r)
      layer_norm_row(x + r * g.cols, gamma, beta, g.cols, eps, y + r * g.cols, mean + r,
                     invstd + r);
  });
}

// in {gy, x, gamma?, mean, invstd}, out {gx?, ggamma?, gbeta?}; gx per row: engine/row_math.h.
void layer_norm_backward(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 5 && a.out.size() == 3);
  const Rows g = rows_of(a.in[1]);
  const float *gy = a.in[0].data<float>(), *x = a.in[1].data<float>();
  const float* gamma = data_or_null(a.in[2]);
  const float *mean = a.in[3].data<float>(), *invstd = a.in[4].data<float>();
  float *gx = out_or_null(a.out[0]), *gg = out_or_null(a.out[1]), *gb = out_or_null(a.out[2]);
  const int max_ranges = max_threads();
  std::vector<double> partial;
  if (gg || gb) partial.assign(static_cast<size_t>(max_ranges * 2 * g.cols), 0.0);
  const int ranges =
      parallel_ranges_indexed(g.rows, 8 * g.cols, max_ranges, [&](int t, int64_t b, int64_t e) {
        double* pg = partial.empty() ? nullptr : partial.data() + t * 2 * g.cols;
        double* pb = pg ? pg + g.cols : nullptr;
        for (int64_t r = b; r < e; ++r) {
          const float *gyr = gy + r * g.cols, *xr = x + r * g.cols;
          if (pg) {
            const float m = mean[r], s = invstd[r];
            for (int64_t c = 0; c < g.cols; ++c) {
              pg[c] += gyr[c] * static_cast<double>((xr[c] - m) * s);
              pb[c] += gyr[c];
            }
          }
          if (gx)
            layer_norm_backward_row(gyr, xr, gamma, mean[r], invstd[r], g.cols, gx + r * g.cols);
        }
      });
  for (int64_t c = 0; c < g.cols; ++c) {
    double sg = 0.0, sb = 0.0;
    for (int t = 0; t < ranges && !partial.empty(); ++t) {
      sg += partial[t * 2 * g.cols + c];
      sb += partial[t * 2 * g.cols + g.cols + c];
    }
    if (gg) gg[c] = static_cast<float>(sg);
    if (gb) gb[c] = static_cast<float>(sb);
  }
}

// in {x}, out {y}: softmax over the last dim, row maximum subtracted.
void softmax(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1);
  const Rows g = rows_of(a.in[0]);
  const float* x = a.in[0].data<float>();
  float* y = a.out[0].data<float>();
  parallel_ranges(g.rows, 24 * g.cols, [&](int64_t b, int64_t e) {
    for (int64_t r = b; r < e; ++r) {
      const float* xr = x + r * g.cols;
      float* yr = y + r * g.cols;
      const float m = *std::max_element(xr, xr + g.cols);
      double s = 0.0;
      for (int64_t c = 0; c < g.cols; ++c) {
        yr[c] = std::exp(xr[c] - m);
        s += yr[c];
      }
      const float inv = static_cast<float>(1.0 / s);
      for (int64_t c = 0; c < g.cols; ++c) yr[c] *= inv;
    }
  });
}

// in {gy, y}, out {gx}: gx = y * (gy - sum gy * y).
void softmax_backward(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 2 && a.out.size() == 1);
  const Rows g = rows_of(a.in[1]);
  const float *gy = a.in[0].data<float>(), *y = a.in[1].data<float>();
  float* gx = a.out[0].data<float>();
  parallel_ranges(g.rows, 4 * g.cols, [&](int64_t b, int64_t e) {
    for (int64_t r = b; r < e; ++r) {
      const float *gyr = gy + r * g.cols, *yr = y + r * g.cols;
      double dot = 0.0;
      for (int64_t c = 0; c < g.cols; ++c) dot += static_cast<double>(gyr[c]) * yr[c];
      const float d = static_cast<float>(dot);
      for (int64_t c = 0; c < g.cols; ++c) gx[r * g.cols + c] = yr[c] * (gyr[c] - d);
    }
  });
}

}  // namespace

void register_row_kernels(KernelRegistry& r) {
  r.add(OpId::layer_norm, DeviceType::cpu, DType::f32, layer_norm, "openmp");
  r.add(OpId::layer_norm_backward, DeviceType::cpu, DType::f32, layer_norm_backward, "openmp");
  r.add(OpId::softmax, DeviceType::cpu, DType::f32, softmax, "openmp");
  r.add(OpId::softmax_backward, DeviceType::cpu, DType::f32, softmax_backward, "openmp");
}

}  // namespace cvd::cpu
