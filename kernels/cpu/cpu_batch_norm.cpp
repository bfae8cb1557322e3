// batch_norm and batch_norm_backward on the CPU, f32, by hand (OpenMP + SIMD): training (batch
// statistics, PyTorch running-stat update with the unbiased variance) and eval (running
// statistics), affine (gamma and/or beta) or not, with an optional fused relu / clip
// (BatchNormParams::fused_act). On NCHW tensors oneDNN 2.6 has only its C++ "ncsp_bnorm"
// (measured at about a quarter of the depth networks' training step forward, and 4-19x slower
// than this backward on the kernel table's shapes); these are vectorized along the planes.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "engine/error.h"
#include "engine/kernel_params.h"
#include "kernels/cpu/cpu_openmp_families.h"
#include "kernels/cpu/cpu_parallel.h"

namespace cvd::cpu {

namespace {

void check_f32(const Tensor& t, const char* what) {
  if (t.dtype() != DType::f32 || !t.is_contiguous()) {
    fail(ErrorCategory::internal,
         "kernels/cpu/cpu_batch_norm.cpp: {} must be a contiguous f32 tensor, got {}", what,
         t.str());
  }
}

void check_channels(const Tensor& t, int64_t c, const char* what) {
  check_f32(t, what);
  if (t.dim() != 1 || t.shape()[0] != c) {
    fail(ErrorCategory::internal,
         "kernels/cpu/cpu_batch_norm.cpp: {} must have {} elements, got {}", what, c, t.str());
  }
}

// x must be [N, C, ...] with 2 to 5 dims.
void check_dims(const Tensor& x) {
  if (x.dim() < 2 || x.dim() > 5) {
    fail(ErrorCategory::unsupported,
         "kernels/cpu/cpu_batch_norm.cpp: batch norm of a {}-d tensor {} (2 to 5 dims supported)",
         x.dim(), x.str());
  }
}

// What both hand-written forwards read: x and y as n * c planes, the optional affine.
struct NormPlanes {
  NormPlanes(const Tensor& x, const Tensor& gamma, const Tensor& beta, const Tensor& y)
      : n(x.shape()[0]),
        c(x.shape()[1]),
        plane(c > 0 ? x.numel() / (n * c) : 0),
        xp(x.data<float>()),
        yp(y.data<float>()),
        g(gamma.defined() ? gamma.data<float>() : nullptr),
        b(beta.defined() ? beta.data<float>() : nullptr) {}
  float gamma_at(int64_t ch) const { return g ? g[ch] : 1.0f; }
  float beta_at(int64_t ch) const { return b ? b[ch] : 0.0f; }
  int64_t n, c, plane;
  const float* xp;
  float* yp;
  const float *g, *b;
};

// dst[k] = act(src[k] * scale + shift) for k < count, act the fused activation if any.
void scale_shift(const float* src, float* dst, int64_t count, float scale, float shift,
                 const BatchNormParams& p) {
  if (!p.fused_act) {
#pragma omp simd
    for (int64_t k = 0; k < count; ++k) dst[k] = src[k] * scale + shift;
  } else if (p.act.op == UnaryOp::relu) {
#pragma omp simd
    for (int64_t k = 0; k < count; ++k) {
      const float v = src[k] * scale + shift;
      dst[k] = v > 0.0f ? v : 0.0f;
    }
  } else {
    const float lo = static_cast<float>(p.act.a), hi = static_cast<float>(p.act.b);
#pragma omp simd
    for (int64_t k = 0; k < count; ++k) {
      const float v = src[k] * scale + shift;
      dst[k] = v < lo ? lo : (v > hi ? hi : v);
    }
  }
}

void check_activation(const BatchNormParams& p) {
  if (p.fused_act && p.act.op != UnaryOp::relu && p.act.op != UnaryOp::clip) {
    fail(ErrorCategory::unsupported,
         "kernels/cpu/cpu_batch_norm.cpp: a fused activation must be relu or clip, got unary "
         "op {}",
         static_cast<int>(p.act.op));
  }
}

// Training forward by hand: per channel, one pass for the batch mean, one for the (biased)
// variance around it (per-plane float sums added in double), and one writing
// y = act((x - mean) * invstd * gamma + beta). var: c floats out.
void batch_norm_train_forward(const Tensor& x, const Tensor& gamma, const Tensor& beta,
                              const Tensor& y, const BatchNormParams& p, float* mean, float* var) {
  const NormPlanes v(x, gamma, beta, y);
  const int64_t n = v.n, c = v.c, plane = v.plane;
  const float* xp = v.xp;
  parallel_ranges(c, 3 * n * plane, [&](int64_t c0, int64_t c1) {
    for (int64_t ch = c0; ch < c1; ++ch) {
      double sum = 0.0;
      for (int64_t i = 0; i < n; ++i) {
        const float* src = xp + (i * c + ch) * plane;
        float s = 0.0f;
#pragma omp simd reduction(+ : s)
        for (int64_t k = 0; k < plane; ++k) s += src[k];
        sum += s;
      }
      const double count = static_cast<double>(n * plane);
      const double m = sum / count;
      const float mf = static_cast<float>(m);
      double sum_sq = 0.0;
      for (int64_t i = 0; i < n; ++i) {
        const float* src = xp + (i * c + ch) * plane;
        float s2 = 0.0f;
#pragma omp simd reduction(+ : s2)
        for (int64_t k = 0; k < plane; ++k) s2 += (src[k] - mf) * (src[k] - mf);
        sum_sq += s2;
      }
      const double variance = sum_sq / count;
      mean[ch] = static_cast<float>(m);
      var[ch] = static_cast<float>(variance);
      const double inv = 1.0 / std::sqrt(variance + p.eps);
      const float scale = static_cast<float>(inv * v.gamma_at(ch));
      const float shift = static_cast<float>(v.beta_at(ch) - m * inv * v.gamma_at(ch));
      for (int64_t i = 0; i < n; ++i) {
        scale_shift(xp + (i * c + ch) * plane, v.yp + (i * c + ch) * plane, plane, scale, shift, p);
      }
    }
  });
}

// Eval forward (running statistics) by hand as well: one vectorized pass y = x * scale + shift
// per channel (oneDNN 2.6's NCHW primitive is its slower C++ path; backward recomputes
// activations through this pass, engine/rematerialize.h).
void run_eval_forward(const Tensor& x, const Tensor& gamma, const Tensor& beta, const Tensor& y,
                      const Tensor& running_mean, const Tensor& running_var,
                      const BatchNormParams& p) {
  const NormPlanes v(x, gamma, beta, y);
  const float* rm = running_mean.data<float>();
  const float* rv = running_var.data<float>();
  parallel_ranges(v.n * v.c, v.plane, [&](int64_t r0, int64_t r1) {
    for (int64_t r = r0; r < r1; ++r) {
      const int64_t ch = r % v.c;
      const double inv = 1.0 / std::sqrt(static_cast<double>(rv[ch]) + p.eps);
      const double gs = inv * v.gamma_at(ch);
      const float scale = static_cast<float>(gs);
      const float shift = static_cast<float>(v.beta_at(ch) - rm[ch] * gs);
      scale_shift(v.xp + r * v.plane, v.yp + r * v.plane, v.plane, scale, shift, p);
    }
  });
}

// in {x, gamma?, beta?, running_mean, running_var}, out {y, mean, invstd}; BatchNormParams.
void batch_norm(const KernelArgs& a) {
  const Tensor &x = a.in[0], &gamma = a.in[1], &beta = a.in[2];
  const Tensor &running_mean = a.in[3], &running_var = a.in[4];
  const Tensor &y = a.out[0], &mean = a.out[1], &invstd = a.out[2];
  const BatchNormParams& p = a.p<BatchNormParams>();
  check_f32(x, "batch_norm input");
  check_dims(x);
  check_f32(y, "batch_norm output");
  check_activation(p);
  const int64_t c = x.shape()[1];
  if (gamma.defined()) check_channels(gamma, c, "batch_norm gamma");
  if (beta.defined()) check_channels(beta, c, "batch_norm beta");
  check_channels(running_mean, c, "batch_norm running mean");
  check_channels(running_var, c, "batch_norm running var");
  check_channels(mean, c, "batch_norm mean output");
  check_channels(invstd, c, "batch_norm invstd output");
  const int64_t count = c > 0 ? x.numel() / c : 0;  // values per channel
  if (p.training && count < 2) {
    fail(ErrorCategory::invalid_argument,
         "kernels/cpu/cpu_batch_norm.cpp: training batch norm needs more than one value per "
         "channel, got {}",
         x.str());
  }
  float* mean_p = mean.data<float>();
  float* invstd_p = invstd.data<float>();
  float* rm = running_mean.data<float>();
  float* rv = running_var.data<float>();
  if (x.numel() == 0) {
    for (int64_t i = 0; i < c; ++i) {
      mean_p[i] = rm[i];
      invstd_p[i] = static_cast<float>(1.0 / std::sqrt(static_cast<double>(rv[i]) + p.eps));
    }
    return;
  }

  std::vector<float> var(p.training ? static_cast<size_t>(c) : 0);
  if (p.training) {
    batch_norm_train_forward(x, gamma, beta, y, p, mean_p, var.data());
  } else {
    run_eval_forward(x, gamma, beta, y, running_mean, running_var, p);
  }

  const double unbias =
      count > 1 ? static_cast<double>(count) / static_cast<double>(count - 1) : 1.0;
  for (int64_t i = 0; i < c; ++i) {
    if (p.training) {
      const double v = var[i];
      invstd_p[i] = static_cast<float>(1.0 / std::sqrt(v + p.eps));
      rm[i] = static_cast<float>((1.0 - p.momentum) * rm[i] + p.momentum * mean_p[i]);
      rv[i] = static_cast<float>((1.0 - p.momentum) * rv[i] + p.momentum * v * unbias);
    } else {
      mean_p[i] = rm[i];
      invstd_p[i] = static_cast<float>(1.0 / std::sqrt(static_cast<double>(rv[i]) + p.eps));
    }
  }
}

// Backward by hand, with the fused activation's mask if any: per channel one pass for
// gbeta = sum gm and ggamma = sum gm * xhat, where gm = gy masked by act' at the recomputed
// pre-activation x * scale + shift, and one writing
//   gx = gamma * invstd * (gm - gbeta / m - xhat * ggamma / m)   (training; eval: gamma * invstd * gm).
// Float sums over blocks of kSumBlock values, added in double.
enum class Mask { none, relu, clip };
constexpr int64_t kSumBlock = 4096;

template <Mask M>
inline float masked(float g, float pre, float lo, float hi) {
  if constexpr (M == Mask::relu) return pre > 0.0f ? g : 0.0f;
  if constexpr (M == Mask::clip) return (pre > lo && pre < hi) ? g : 0.0f;
  return g;
}

struct BackwardPlanes {
  int64_t n, c, plane;
  const float *gy, *x, *gamma, *beta, *mean, *invstd;
  float *gx, *ggamma, *gbeta;
  bool training;
  float lo, hi;
};

template <Mask M>
void backward_channels(const BackwardPlanes& v, int64_t c0, int64_t c1) {
  const float lo = v.lo, hi = v.hi;
  const double m = static_cast<double>(v.n * v.plane);
  for (int64_t ch = c0; ch < c1; ++ch) {
    const double inv = v.invstd[ch], gam = v.gamma ? v.gamma[ch] : 1.0;
    const double bet = v.beta ? v.beta[ch] : 0.0;
    const float mf = v.mean[ch];
    const float scale = static_cast<float>(inv * gam);
    const float shift = static_cast<float>(bet - mf * inv * gam);
    double sum_g = 0.0, sum_gd = 0.0;  // sum gm, sum gm * (x - mean)
    for (int64_t i = 0; i < v.n; ++i) {
      const float* xs = v.x + (i * v.c + ch) * v.plane;
      const float* gs = v.gy + (i * v.c + ch) * v.plane;
      for (int64_t k0 = 0; k0 < v.plane; k0 += kSumBlock) {
        const int64_t k1 = std::min(v.plane, k0 + kSumBlock);
        float a = 0.0f, b = 0.0f;
#pragma omp simd reduction(+ : a, b)
        for (int64_t k = k0; k < k1; ++k) {
          const float gm = masked<M>(gs[k], xs[k] * scale + shift, lo, hi);
          a += gm;
          b += gm * (xs[k] - mf);
        }
        sum_g += a;
        sum_gd += b;
      }
    }
    const double sum_gxhat = sum_gd * inv;
    if (v.gbeta) v.gbeta[ch] = static_cast<float>(sum_g);
    if (v.ggamma) v.ggamma[ch] = static_cast<float>(sum_gxhat);
    if (!v.gx) continue;
    // gx = a * gm - b * (x - mean) - d.
    const float a = static_cast<float>(gam * inv);
    const float b = v.training ? static_cast<float>(gam * inv * inv * sum_gxhat / m) : 0.0f;
    const float d = v.training ? static_cast<float>(gam * inv * sum_g / m) : 0.0f;
    for (int64_t i = 0; i < v.n; ++i) {
      const float* xs = v.x + (i * v.c + ch) * v.plane;
      const float* gs = v.gy + (i * v.c + ch) * v.plane;
      float* out = v.gx + (i * v.c + ch) * v.plane;
#pragma omp simd
      for (int64_t k = 0; k < v.plane; ++k) {
        const float gm = masked<M>(gs[k], xs[k] * scale + shift, lo, hi);
        out[k] = a * gm - b * (xs[k] - mf) - d;
      }
    }
  }
}

void run_backward_by_hand(const KernelArgs& a) {
  const BatchNormParams& p = a.p<BatchNormParams>();
  const Tensor& x = a.in[1];
  const Tensor& beta = p.fused_act ? a.in[5] : Tensor();
  BackwardPlanes v;
  v.n = x.shape()[0];
  v.c = x.shape()[1];
  v.plane = v.c > 0 ? x.numel() / (v.n * v.c) : 0;
  v.gy = a.in[0].data<float>();
  v.x = x.data<float>();
  v.gamma = a.in[2].defined() ? a.in[2].data<float>() : nullptr;
  v.beta = beta.defined() ? beta.data<float>() : nullptr;
  v.mean = a.in[3].data<float>();
  v.invstd = a.in[4].data<float>();
  v.gx = a.out[0].defined() ? a.out[0].data<float>() : nullptr;
  v.ggamma = a.out[1].defined() ? a.out[1].data<float>() : nullptr;
  v.gbeta = a.out[2].defined() ? a.out[2].data<float>() : nullptr;
  v.training = p.training;
  v.lo = static_cast<float>(p.act.a);
  v.hi = static_cast<float>(p.act.b);
  const Mask mask = !p.fused_act ? Mask::none : p.act.op == UnaryOp::relu ? Mask::relu : Mask::clip;
  parallel_ranges(v.c, 4 * v.n * v.plane, [&](int64_t c0, int64_t c1) {
    switch (mask) {
      case Mask::none:
        return backward_channels<Mask::none>(v, c0, c1);
      case Mask::relu:
        return backward_channels<Mask::relu>(v, c0, c1);
      case Mask::clip:
        return backward_channels<Mask::clip>(v, c0, c1);
    }
  });
}

// in {gy, x, gamma?, mean, invstd}, out {gx?, ggamma?, gbeta?}; BatchNormParams. Training:
// gradient through the batch statistics; eval: statistics are constants.
void batch_norm_backward(const KernelArgs& a) {
  const Tensor &gy = a.in[0], &x = a.in[1], &gamma = a.in[2], &mean = a.in[3], &invstd = a.in[4];
  const Tensor &gx = a.out[0], &ggamma = a.out[1], &gbeta = a.out[2];
  const BatchNormParams& p = a.p<BatchNormParams>();
  check_f32(gy, "batch_norm_backward output gradient");
  check_f32(x, "batch_norm_backward input");
  check_dims(x);
  const int64_t c = x.shape()[1];
  if (gamma.defined()) check_channels(gamma, c, "batch_norm_backward gamma");
  check_channels(mean, c, "batch_norm_backward mean");
  check_channels(invstd, c, "batch_norm_backward invstd");
  if (gx.defined()) check_f32(gx, "batch_norm_backward input gradient");
  if (ggamma.defined()) check_channels(ggamma, c, "batch_norm_backward gamma gradient");
  if (gbeta.defined()) check_channels(gbeta, c, "batch_norm_backward beta gradient");
  if (ggamma.defined() && !gamma.defined()) {
    fail(ErrorCategory::internal,
         "kernels/cpu/cpu_batch_norm.cpp: a gamma gradient was requested without gamma");
  }
  check_activation(p);
  if (p.fused_act) {
    if (a.in.size() != 6) {
      fail(ErrorCategory::internal,
           "kernels/cpu/cpu_batch_norm.cpp: a fused activation's backward needs beta (undefined "
           "for none) as a sixth input");
    }
    if (a.in[5].defined()) check_channels(a.in[5], c, "batch_norm_backward beta");
  }
  if (!gx.defined() && !ggamma.defined() && !gbeta.defined()) return;
  if (x.numel() == 0) {
    for (const Tensor* t : {&ggamma, &gbeta}) {
      if (t->defined()) std::memset(t->data_ptr(), 0, t->nbytes());
    }
    return;
  }
  run_backward_by_hand(a);
}

}  // namespace

void register_batch_norm_kernels(KernelRegistry& r) {
  r.add(OpId::batch_norm, DeviceType::cpu, DType::f32, batch_norm, "openmp");
  r.add(OpId::batch_norm_backward, DeviceType::cpu, DType::f32, batch_norm_backward, "openmp");
}

}  // namespace cvd::cpu
