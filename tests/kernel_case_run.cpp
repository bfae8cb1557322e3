// Part of the cvd_test_support library linked into every test executable.
#include "tests/kernel_case_run.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

namespace cvd::test {

namespace {

// `t` on `device` with the same view: its whole storage copied, then the same shape, strides and
// offset over the copy (a transposed or broadcast input stays one on the device).
Tensor on_device(const Tensor& t, DeviceId device) {
  if (!t.defined() || t.device() == device) return t;
  const int64_t n = static_cast<int64_t>(t.storage()->nbytes() / t.element_size());
  const Tensor copy = Tensor::from_storage(t.storage(), {n}, t.dtype()).to(device);
  return strided_view(copy, t.shape(), t.strides(), t.offset());
}

Tensor nan_filled(const Shape& shape, DType dtype, DeviceId device) {
  if (shape == kUndefined) return Tensor();
  Tensor t = Tensor::empty(shape, dtype);
  if (dtype == DType::f64) {
    std::fill_n(t.data<double>(), t.numel(), std::numeric_limits<double>::quiet_NaN());
  } else {
    std::fill_n(t.data<float>(), t.numel(), std::numeric_limits<float>::quiet_NaN());
  }
  return on_device(t, device);
}

// max |got - want| <= tol * max(max |want|, min_scale); NaN fails. The first mismatch and the count, or "".
std::string mismatch(const std::vector<double>& got, const std::vector<double>& want, double tol,
                     double min_scale, const std::string& what) {
  if (got.size() != want.size())
    return fmt::format("{}: {} elements, reference {}", what, got.size(), want.size());
  double scale = 0.0;
  for (double v : want) scale = std::max(scale, std::abs(v));
  const double bound = tol * std::max({scale, min_scale, 1e-30});
  int64_t bad = 0, first = -1;
  for (size_t i = 0; i < got.size(); ++i) {
    if (!(std::abs(got[i] - want[i]) <= bound)) {
      if (first < 0) first = static_cast<int64_t>(i);
      ++bad;
    }
  }
  if (bad == 0) return "";
  return fmt::format(
      "{}: {} of {} elements off by more than {:.3g}; first at {}: {} vs reference {}", what, bad,
      got.size(), bound, first, got[first], want[first]);
}

}  // namespace

std::vector<std::vector<double>> reference_outputs(OpId op, const std::vector<Pair>& in,
                                                   const std::vector<Shape>& out,
                                                   const void* params) {
  const KernelInfo* ref = kernel_registry().find(op, DeviceType::cpu, DType::f64);
  if (!ref) throw std::logic_error(fmt::format("no reference kernel of {}", op_name(op)));
  KernelArgs a;
  a.params = params;
  // Copies: an in-place kernel (batch norm's running statistics) must not change the call's inputs.
  for (const Pair& p : in) a.in.push_back(p.t64.defined() ? p.t64.clone() : Tensor());
  for (const Shape& s : out) a.out.push_back(nan_filled(s, DType::f64, DeviceId::cpu()));
  ref->fn(a);
  std::vector<std::vector<double>> values;
  for (const Tensor& t : a.out)
    values.push_back(t.defined() ? t.to_vector() : std::vector<double>{});
  return values;
}

KernelArgs kernel_args(const KernelCall& call, bool reference, DeviceId device) {
  KernelArgs a;
  a.params = call.params.get();
  for (const Pair& p : call.in) a.in.push_back(on_device(reference ? p.t64 : p.t32, device));
  for (const Shape& s : call.out)
    a.out.push_back(nan_filled(s, reference ? DType::f64 : call.out_dtype, device));
  return a;
}

std::string compare_call_with_reference(const KernelCall& call, const KernelBackend& backend) {
  const std::string what = fmt::format("{} [{}]", call.what, backend.name);
  const KernelInfo* ref = kernel_registry().find(call.op, DeviceType::cpu, DType::f64);
  const KernelInfo* fast = kernel_registry().find(call.op, backend.type, DType::f32);
  if (!ref) return fmt::format("{}: no reference kernel of {}", what, op_name(call.op));
  if (!fast) return fmt::format("{}: no f32 kernel of {}", what, op_name(call.op));
  const bool impl_ok =
      backend.impl.empty() ? std::strcmp(fast->impl, ref->impl) != 0 : backend.impl == fast->impl;
  if (!impl_ok)
    return fmt::format("{}: the f32 kernel of {} is impl '{}', not {}", what, op_name(call.op),
                       fast->impl, backend.impl.empty() ? "a fast one" : "'" + backend.impl + "'");
  const KernelArgs a32 = kernel_args(call, false, backend.device);
  const KernelArgs a64 = kernel_args(call, true, DeviceId::cpu());
  fast->fn(a32);
  ref->fn(a64);
  for (size_t i = 0; i < call.out.size(); ++i) {
    if (!a64.out[i].defined()) continue;
    const std::string m = mismatch(a32.out[i].to_vector(), a64.out[i].to_vector(), call.tol,
                                   call.min_scale, fmt::format("{} output {}", what, i));
    if (!m.empty()) return m;
  }
  if (call.read_inputs) {
    for (size_t i = 0; i < call.in.size(); ++i) {
      if (!a64.in[i].defined()) continue;
      const std::string m =
          mismatch(a32.in[i].to_vector(), a64.in[i].to_vector(), call.tol, call.min_scale,
                   fmt::format("{} input {} after the call", what, i));
      if (!m.empty()) return m;
    }
  }
  return "";
}

}  // namespace cvd::test
