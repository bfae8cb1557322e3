// batch_norm and batch_norm_backward on oneDNN batch-normalization primitives (NCHW, in place of
// nothing): training (batch statistics, PyTorch running-stat update with the unbiased variance)
// and eval (running statistics), affine (gamma and/or beta) or not. Both forwards run by
// hand: on NCHW tensors oneDNN 2.6 only has its C++ "ncsp_bnorm" (three passes over the data,
// measured at about a quarter of the depth networks' training step); ours is vectorized.
#include <algorithm>
#include <cmath>
#include <cstring>

#include "engine/error.h"
#include "engine/kernel_params.h"
#include "kernels/cpu/cpu_parallel.h"
#include "kernels/cpu/onednn_context.h"
#include "kernels/cpu/onednn_kernels.h"

namespace cvd::onednn {

namespace {

using tag = dnnl::memory::format_tag;
using flags = dnnl::normalization_flags;

void check_f32(const Tensor& t, const char* what) {
  if (t.dtype() != DType::f32 || !t.is_contiguous()) {
    fail(ErrorCategory::internal,
         "kernels/cpu/onednn_batch_norm.cpp: {} must be a contiguous f32 tensor, got {}", what,
         t.str());
  }
}

void check_channels(const Tensor& t, int64_t c, const char* what) {
  check_f32(t, what);
  if (t.dim() != 1 || t.shape()[0] != c) {
    fail(ErrorCategory::internal,
         "kernels/cpu/onednn_batch_norm.cpp: {} must have {} elements, got {}", what, c, t.str());
  }
}

// x [N, C, ...] (2 to 5 dims) as a oneDNN plain descriptor.
dnnl::memory::desc data_desc(const Tensor& x) {
  static const tag tags[] = {tag::nc, tag::ncw, tag::nchw, tag::ncdhw};
  if (x.dim() < 2 || x.dim() > 5) {
    fail(
        ErrorCategory::unsupported,
        "kernels/cpu/onednn_batch_norm.cpp: batch norm of a {}-d tensor {} (2 to 5 dims supported)",
        x.dim(), x.str());
  }
  return dnnl::memory::desc(dnnl::memory::dims(x.shape().begin(), x.shape().end()),
                            dnnl::memory::data_type::f32, tags[x.dim() - 2]);
}

dnnl::memory::desc channel_desc(int64_t c) {
  return dnnl::memory::desc({c}, dnnl::memory::data_type::f32, tag::x);
}

int64_t float_bits(double v) {
  const float f = static_cast<float>(v);
  int32_t bits = 0;
  std::memcpy(&bits, &f, sizeof bits);
  return bits;
}

flags with(flags a, flags b) {
  return static_cast<flags>(static_cast<unsigned>(a) | static_cast<unsigned>(b));
}

// oneDNN 2.6's backward pass with use_shift wants the (unused) shift as an input too.
dnnl::memory zero_shift(const dnnl::memory::desc& cmd, int64_t c) {
  float* zeros = static_cast<float*>(scratch_buffer(3, static_cast<size_t>(c) * sizeof(float)));
  std::fill(zeros, zeros + c, 0.0f);
  return dnnl::memory(cmd, cpu_engine(), zeros);
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

// dst[k] = src[k] * scale + shift for k < count.
void scale_shift(const float* src, float* dst, int64_t count, float scale, float shift) {
#pragma omp simd
  for (int64_t k = 0; k < count; ++k) dst[k] = src[k] * scale + shift;
}

// Training forward by hand: per channel, one pass for the batch mean, one for the (biased)
// variance around it (per-plane float sums added in double), and one writing
// y = (x - mean) * invstd * gamma + beta. var: c floats out.
void batch_norm_train_forward(const Tensor& x, const Tensor& gamma, const Tensor& beta,
                              const Tensor& y, double eps, float* mean, float* var) {
  const NormPlanes v(x, gamma, beta, y);
  const int64_t n = v.n, c = v.c, plane = v.plane;
  const float* xp = v.xp;
  cpu::parallel_ranges(c, 3 * n * plane, [&](int64_t c0, int64_t c1) {
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
      const double inv = 1.0 / std::sqrt(variance + eps);
      const float scale = static_cast<float>(inv * v.gamma_at(ch));
      const float shift = static_cast<float>(v.beta_at(ch) - m * inv * v.gamma_at(ch));
      for (int64_t i = 0; i < n; ++i) {
        scale_shift(xp + (i * c + ch) * plane, v.yp + (i * c + ch) * plane, plane, scale, shift);
      }
    }
  });
}

struct BackwardEntry {
  dnnl::batch_normalization_backward prim;
};

// Eval forward (running statistics) by hand as well: one vectorized pass y = x * scale + shift
// per channel (oneDNN 2.6's NCHW primitive is its slower C++ path; backward recomputes
// activations through this pass, engine/rematerialize.h).
void run_eval_forward(const Tensor& x, const Tensor& gamma, const Tensor& beta, const Tensor& y,
                      const Tensor& running_mean, const Tensor& running_var,
                      const BatchNormParams& p) {
  const NormPlanes v(x, gamma, beta, y);
  const float* rm = running_mean.data<float>();
  const float* rv = running_var.data<float>();
  cpu::parallel_ranges(v.n * v.c, v.plane, [&](int64_t r0, int64_t r1) {
    for (int64_t r = r0; r < r1; ++r) {
      const int64_t ch = r % v.c;
      const double inv = 1.0 / std::sqrt(static_cast<double>(rv[ch]) + p.eps);
      const double gs = inv * v.gamma_at(ch);
      const float scale = static_cast<float>(gs);
      const float shift = static_cast<float>(v.beta_at(ch) - rm[ch] * gs);
      scale_shift(v.xp + r * v.plane, v.yp + r * v.plane, v.plane, scale, shift);
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
  check_f32(y, "batch_norm output");
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
         "kernels/cpu/onednn_batch_norm.cpp: training batch norm needs more than one value per "
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

  float* var = nullptr;
  if (p.training) {
    var = static_cast<float*>(scratch_buffer(0, static_cast<size_t>(c) * sizeof(float)));
    batch_norm_train_forward(x, gamma, beta, y, p.eps, mean_p, var);
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

// in {gy, x, gamma?, mean, invstd}, out {gx?, ggamma?, gbeta?}; BatchNormParams. Training:
// gradient through the batch statistics; eval: statistics are constants.
void batch_norm_backward(const KernelArgs& a) {
  static PrimitiveCache<BackwardEntry> cache;
  const Tensor &gy = a.in[0], &x = a.in[1], &gamma = a.in[2], &mean = a.in[3], &invstd = a.in[4];
  const Tensor &gx = a.out[0], &ggamma = a.out[1], &gbeta = a.out[2];
  const BatchNormParams& p = a.p<BatchNormParams>();
  check_f32(gy, "batch_norm_backward output gradient");
  check_f32(x, "batch_norm_backward input");
  const int64_t c = x.shape()[1];
  if (gamma.defined()) check_channels(gamma, c, "batch_norm_backward gamma");
  check_channels(mean, c, "batch_norm_backward mean");
  check_channels(invstd, c, "batch_norm_backward invstd");
  if (gx.defined()) check_f32(gx, "batch_norm_backward input gradient");
  if (ggamma.defined()) check_channels(ggamma, c, "batch_norm_backward gamma gradient");
  if (gbeta.defined()) check_channels(gbeta, c, "batch_norm_backward beta gradient");
  if (ggamma.defined() && !gamma.defined()) {
    fail(ErrorCategory::internal,
         "kernels/cpu/onednn_batch_norm.cpp: a gamma gradient was requested without gamma");
  }
  if (!gx.defined() && !ggamma.defined() && !gbeta.defined()) return;
  if (x.numel() == 0) {
    for (const Tensor* t : {&ggamma, &gbeta}) {
      if (t->defined()) std::memset(t->data_ptr(), 0, t->nbytes());
    }
    return;
  }

  // oneDNN's backward_data accepts no scale or shift: an affine layer always runs the full
  // backward (a gamma gradient nobody asked for goes to scratch).
  const bool param_grads = gamma.defined() || gbeta.defined();
  flags f = flags::none;
  if (gamma.defined()) f = with(f, flags::use_scale);
  if (gbeta.defined()) f = with(f, flags::use_shift);
  if (!p.training) f = with(f, flags::use_global_stats);
  const dnnl::memory::desc md = data_desc(x);
  CacheKey key;
  key.add(2).add(x.shape()).add(static_cast<int64_t>(f)).add(float_bits(p.eps));
  key.add(param_grads ? 1 : 0).add(onednn_threads());
  BackwardEntry& e = cache.get(key, [&] {
    const float eps = static_cast<float>(p.eps);
    dnnl::batch_normalization_forward::desc fd(dnnl::prop_kind::forward_training, md, eps, f);
    dnnl::batch_normalization_forward::primitive_desc hint(fd, cpu_engine());
    dnnl::batch_normalization_backward::desc d(
        param_grads ? dnnl::prop_kind::backward : dnnl::prop_kind::backward_data, md, md, eps, f);
    auto entry = std::make_unique<BackwardEntry>();
    entry->prim = dnnl::batch_normalization_backward(
        dnnl::batch_normalization_backward::primitive_desc(d, cpu_engine(), hint));
    return entry;
  });

  // oneDNN takes the variance; recover it from invstd = 1 / sqrt(var + eps).
  float* var = static_cast<float*>(scratch_buffer(0, static_cast<size_t>(c) * sizeof(float)));
  const float* invstd_p = invstd.data<float>();
  for (int64_t i = 0; i < c; ++i) {
    const double s = invstd_p[i];
    var[i] = static_cast<float>(std::max(0.0, 1.0 / (s * s) - p.eps));
  }
  dnnl::engine& eng = cpu_engine();
  const dnnl::memory::desc cmd = channel_desc(c);
  std::unordered_map<int, dnnl::memory> args = {{DNNL_ARG_SRC, tensor_memory(x, md)},
                                                {DNNL_ARG_DIFF_DST, tensor_memory(gy, md)},
                                                {DNNL_ARG_MEAN, tensor_memory(mean, cmd)},
                                                {DNNL_ARG_VARIANCE, dnnl::memory(cmd, eng, var)}};
  args[DNNL_ARG_DIFF_SRC] = gx.defined() ? tensor_memory(gx, md)
                                         : dnnl::memory(md, eng, scratch_buffer(1, md.get_size()));
  if (gamma.defined()) {
    args[DNNL_ARG_SCALE] = tensor_memory(gamma, cmd);
    args[DNNL_ARG_DIFF_SCALE] = ggamma.defined()
                                    ? tensor_memory(ggamma, cmd)
                                    : dnnl::memory(cmd, eng, scratch_buffer(2, cmd.get_size()));
  }
  if (gbeta.defined()) {
    args[DNNL_ARG_SHIFT] = zero_shift(cmd, c);
    args[DNNL_ARG_DIFF_SHIFT] = tensor_memory(gbeta, cmd);
  }
  e.prim.execute(cpu_stream(), args);
  cpu_stream().wait();
}

}  // namespace

void register_batch_norm_kernels(KernelRegistry& r) {
  r.add(OpId::batch_norm, DeviceType::cpu, DType::f32, guarded<OpId::batch_norm, batch_norm>,
        "onednn");
  r.add(OpId::batch_norm_backward, DeviceType::cpu, DType::f32,
        guarded<OpId::batch_norm_backward, batch_norm_backward>, "onednn");
}

}  // namespace cvd::onednn
