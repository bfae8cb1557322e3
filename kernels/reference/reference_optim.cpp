// Reference kernels of the optimiser steps: Adam and SGD (momentum, dampening, Nesterov, weight
// decay), exactly as PyTorch's torch.optim (single-tensor path). They update their state tensors
// in place and leave the gradient untouched.
#include <cmath>

#include "engine/kernel_params.h"
#include "kernels/reference/reference_access.h"
#include "kernels/reference/reference_kernels.h"

namespace cvd::reference {

// in {param, grad, m, v} (param, m, v updated in place), out {}; AdamParams (step already
// incremented, >= 1).
void adam_update(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 4 && a.out.empty() && a.params != nullptr);
  const Tensor& param = a.in[0];
  const Tensor& grad = a.in[1];
  const Tensor& m = a.in[2];
  const Tensor& v = a.in[3];
  for (const Tensor* t : {&param, &grad, &m, &v}) {
    CVD_ASSERT(is_f64_contiguous(*t) && t->shape() == param.shape());
  }
  const AdamParams& p = a.p<AdamParams>();
  CVD_ASSERT(p.step >= 1);
  const double bias_correction1 = 1.0 - std::pow(p.beta1, static_cast<double>(p.step));
  const double bias_correction2 = 1.0 - std::pow(p.beta2, static_cast<double>(p.step));
  double* pp = param.data<double>();
  const double* gp = grad.data<double>();
  double* mp = m.data<double>();
  double* vp = v.data<double>();
  for (int64_t i = 0; i < param.numel(); ++i) {
    const double g = gp[i] + p.weight_decay * pp[i];
    mp[i] = p.beta1 * mp[i] + (1.0 - p.beta1) * g;
    vp[i] = p.beta2 * vp[i] + (1.0 - p.beta2) * g * g;
    const double denom = std::sqrt(vp[i]) / std::sqrt(bias_correction2) + p.eps;
    pp[i] -= p.lr / bias_correction1 * mp[i] / denom;
  }
}

// in {param, grad, buf} (param and buf updated in place; buf may be undefined when momentum is
// 0), out {}; SgdParams. On the first step the momentum buffer starts as the gradient.
void sgd_update(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 3 && a.out.empty() && a.params != nullptr);
  const Tensor& param = a.in[0];
  const Tensor& grad = a.in[1];
  const Tensor& buf = a.in[2];
  const SgdParams& p = a.p<SgdParams>();
  CVD_ASSERT(is_f64_contiguous(param) && is_f64_contiguous(grad));
  CVD_ASSERT(grad.shape() == param.shape());
  const bool use_momentum = p.momentum != 0.0;
  CVD_ASSERT(!use_momentum || (is_f64_contiguous(buf) && buf.shape() == param.shape()));
  double* pp = param.data<double>();
  const double* gp = grad.data<double>();
  double* bp = use_momentum ? buf.data<double>() : nullptr;
  for (int64_t i = 0; i < param.numel(); ++i) {
    double g = gp[i] + p.weight_decay * pp[i];
    if (use_momentum) {
      bp[i] = p.first_step ? g : p.momentum * bp[i] + (1.0 - p.dampening) * g;
      g = p.nesterov ? g + p.momentum * bp[i] : bp[i];
    }
    pp[i] -= p.lr * g;
  }
}

}  // namespace cvd::reference
