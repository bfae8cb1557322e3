// OpenMP f32 kernels of the optimiser steps (PyTorch torch.optim.Adam and SGD), updating the
// parameter and its state in place. The per-element math is the shared
// engine/elementwise_math.h; the per-step scalars are computed once in double.
#include <cmath>

#include "engine/elementwise_math.h"
#include "kernels/cpu/cpu_openmp_families.h"
#include "kernels/cpu/cpu_parallel.h"

namespace cvd::cpu {

namespace {

void check_state(const Tensor& t, const Tensor& param) {
  CVD_ASSERT(t.defined() && t.device().is_cpu() && t.dtype() == DType::f32);
  CVD_ASSERT(t.is_contiguous() && t.shape() == param.shape());
}

// in {param, grad, m, v}, all updated in place except grad; AdamParams.
void adam_update(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 4 && a.params != nullptr);
  const Tensor& param = a.in[0];
  for (const Tensor& t : a.in) check_state(t, param);
  const AdamParams& p = a.p<AdamParams>();
  CVD_ASSERT(p.step >= 1);
  const double t = static_cast<double>(p.step);
  const float step_size = static_cast<float>(p.lr / (1.0 - std::pow(p.beta1, t)));
  const float bc2_sqrt = static_cast<float>(std::sqrt(1.0 - std::pow(p.beta2, t)));
  const float beta1 = static_cast<float>(p.beta1), beta2 = static_cast<float>(p.beta2);
  const float eps = static_cast<float>(p.eps), wd = static_cast<float>(p.weight_decay);
  float* pp = a.in[0].data<float>();
  const float* gp = a.in[1].data<float>();
  float* mp = a.in[2].data<float>();
  float* vp = a.in[3].data<float>();
  parallel_ranges(param.numel(), 8, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) {
      adam_update_element<float>(pp[i], gp[i], mp[i], vp[i], beta1, beta2, eps, wd, step_size,
                                 bc2_sqrt);
    }
  });
}

// in {param, grad, buf (undefined or unused when momentum == 0)}, updated in place; SgdParams.
void sgd_update(const KernelArgs& a) {
  CVD_ASSERT((a.in.size() == 3 || a.in.size() == 2) && a.params != nullptr);
  const Tensor& param = a.in[0];
  check_state(param, param);
  check_state(a.in[1], param);
  const SgdParams& p = a.p<SgdParams>();
  const bool has_buf = a.in.size() == 3 && a.in[2].defined();
  CVD_ASSERT(p.momentum == 0.0 || has_buf);
  if (has_buf) check_state(a.in[2], param);
  float* pp = param.data<float>();
  const float* gp = a.in[1].data<float>();
  float* bp = has_buf ? a.in[2].data<float>() : nullptr;
  const float lr = static_cast<float>(p.lr), momentum = static_cast<float>(p.momentum);
  const float dampening = static_cast<float>(p.dampening);
  const float wd = static_cast<float>(p.weight_decay);
  parallel_ranges(param.numel(), 4, [&](int64_t b, int64_t e) {
    float unused = 0.0f;
    for (int64_t i = b; i < e; ++i) {
      float& buf = bp ? bp[i] : unused;
      sgd_update_element<float>(pp[i], gp[i], buf, lr, momentum, dampening, wd, p.nesterov,
                                p.first_step);
    }
  });
}

}  // namespace

void register_optimizer_kernels(KernelRegistry& r) {
  r.add(OpId::adam_update, DeviceType::cpu, DType::f32, adam_update, "openmp");
  r.add(OpId::sgd_update, DeviceType::cpu, DType::f32, sgd_update, "openmp");
}

}  // namespace cvd::cpu
