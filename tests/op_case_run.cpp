// Part of the cvd_test_support library linked into every test executable.
#include "tests/op_case_run.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <memory>

#include "engine/autograd.h"

namespace cvd::test {

double max_abs(const std::vector<double>& v) {
  double m = 0;
  for (double x : v) m = std::max(m, std::abs(x));
  return m;
}

namespace {

// The first element of `got` farther than `tol` from `want`, as a message; empty if none.
std::string first_mismatch(const std::vector<double>& got, const std::vector<double>& want,
                           double tol, const std::string& what) {
  if (got.size() != want.size())
    return fmt::format("{}: {} elements, reference {}", what, got.size(), want.size());
  for (size_t k = 0; k < want.size(); ++k)
    if (!(std::abs(got[k] - want[k]) <= tol))  // NaN fails too
      return fmt::format("{} element {}: {} vs reference {} (tolerance {:.3g})", what, k, got[k],
                         want[k], tol);
  return "";
}

// `t` (f32, on its device) as a non-contiguous view with the same values: stored with its last
// two dims swapped when both are longer than 1, otherwise every element two apart along its
// longest dim (the other half of the storage is padding).
Tensor strided_copy(const Tensor& t) {
  NoGradGuard ng;
  const int r = static_cast<int>(t.dim());
  if (r >= 2 && t.size(r - 1) > 1 && t.size(r - 2) > 1)
    return t.transpose(r - 2, r - 1).contiguous().transpose(r - 2, r - 1);
  int d = 0;
  for (int k = 1; k < r; ++k)
    if (t.size(k) > t.size(d)) d = k;
  if (r == 0 || t.size(d) < 2) return t;
  const Tensor last = t.transpose(d, r - 1);  // the longest dim last
  // [..., n, 2] with the values in [..., :, 0]; the view drops the trailing 2.
  const Tensor spread = pad(last.unsqueeze(r), {0, 1});
  auto impl = std::make_shared<TensorImpl>();
  impl->storage = spread.storage();
  impl->shape = last.shape();
  impl->strides = Shape(spread.strides().begin(), spread.strides().end() - 1);
  impl->offset = spread.offset();
  impl->dtype = spread.dtype();
  return Tensor(std::move(impl)).transpose(d, r - 1);
}

}  // namespace

Tensor make_case_input(const InputSpec& s, Generator& g) {
  std::vector<double> v(shape_numel(s.shape));
  for (auto& x : v) {
    switch (s.init) {
      case Init::normal:
        x = g.normal();
        break;
      case Init::positive:
        x = 0.5 + 1.5 * g.uniform();
        break;
      case Init::away_from_zero:
        x = (0.2 + g.uniform()) * (g.uniform() < 0.5 ? -1 : 1);
        break;
      case Init::grid:
        x = -1.1 + 2.2 * g.uniform();
        break;
      case Init::mask:
        x = g.uniform() < 0.5 ? 0.0 : 1.0;
        break;
    }
  }
  return Tensor::from_vector(v, s.shape, DType::f64);
}

std::vector<Tensor> make_case_inputs(const OpCase& c, uint64_t seed) {
  Generator g(seed);
  std::vector<Tensor> in;
  for (const auto& s : c.inputs) {
    Tensor t = make_case_input(s, g);
    if (s.differentiable) t.requires_grad_(true);
    in.push_back(t);
  }
  return in;
}

std::vector<double> run_case_f32(const OpCase& c, DeviceId device, uint64_t seed) {
  NoGradGuard ng;
  std::vector<Tensor> in;
  for (const Tensor& t : make_case_inputs(c, seed))
    in.push_back(t.detach().to(DType::f32).to(device));
  return c.fn(in).to_vector();
}

std::string compare_with_reference(const OpCase& c, DeviceId device, uint64_t seed,
                                   const CompareOptions& o) {
  const std::vector<Tensor> in64 = make_case_inputs(c, seed);
  std::vector<Tensor> in32;
  for (const Tensor& t : in64) {
    Tensor u = t.detach().to(DType::f32).to(device);
    if (o.strided_inputs) {
      u = strided_copy(u);
      if (u.dim() >= 1 && u.numel() > 1 && u.is_contiguous())
        return c.name + ": could not make a non-contiguous input";
    }
    if (t.requires_grad()) u.requires_grad_(true);
    in32.push_back(u);
  }
  const double tol = std::max(c.f32_tol, o.min_tol);
  const Tensor out64 = c.fn(in64);
  const Tensor out32 = c.fn(in32);
  if (out32.dtype() != DType::f32) return c.name + ": the f32 run's output is not f32";
  if (out32.device() != device) return c.name + ": output on " + out32.str();
  if (out32.shape() != out64.shape()) return c.name + ": output shape differs from the reference";
  const std::vector<double> r = out64.to_vector();
  std::string m =
      first_mismatch(out32.to_vector(), r, tol * std::max(1.0, max_abs(r)), c.name + ": output");
  if (!m.empty()) return m;

  Generator g(seed + 1);
  const Tensor weights = Tensor::randn(out64.shape(), g, DType::f64);
  std::vector<Tensor> d64, d32;
  for (size_t i = 0; i < in64.size(); ++i)
    if (in64[i].requires_grad()) {
      d64.push_back(in64[i]);
      d32.push_back(in32[i]);
    }
  if (d64.empty()) return "";
  const std::vector<Tensor> g64 = grad(sum(mul(out64, weights)), d64);
  const std::vector<Tensor> g32 = grad(sum(mul(out32, weights.to(DType::f32).to(device))), d32);
  for (size_t i = 0; i < g64.size(); ++i) {
    const std::vector<double> a = g64[i].to_vector();
    m = first_mismatch(g32[i].to_vector(), a, tol * 4 * std::max(1.0, max_abs(a)),
                       c.name + ": gradient of input " + std::to_string(i));
    if (!m.empty()) return m;
  }
  return "";
}

}  // namespace cvd::test
