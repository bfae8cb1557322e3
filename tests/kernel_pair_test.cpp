// See kernel_pair_test.h.
#include "tests/kernel_pair_test.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace cvd::kernel_pair_test {

Pair make_pair(std::vector<double> values, const Shape& shape) {
  for (double& v : values) v = static_cast<double>(static_cast<float>(v));
  return {Tensor::from_vector(values, shape, DType::f64),
          Tensor::from_vector(values, shape, DType::f32)};
}

Pair normal(const Shape& shape, Generator& gen, double std, double mean) {
  std::vector<double> v(static_cast<size_t>(shape_numel(shape)));
  for (double& x : v) x = mean + std * gen.normal();
  return make_pair(v, shape);
}

Pair uniform(const Shape& shape, Generator& gen, double lo, double hi) {
  std::vector<double> v(static_cast<size_t>(shape_numel(shape)));
  for (double& x : v) x = lo + (hi - lo) * gen.uniform();
  return make_pair(v, shape);
}

Pair outputs(const Shape& shape) {
  return make_pair(std::vector<double>(static_cast<size_t>(shape_numel(shape)),
                                       std::numeric_limits<double>::quiet_NaN()),
                   shape);
}

Pair none() { return {}; }

const KernelInfo& kernel(OpId op, DType dt) {
  const KernelInfo* k = kernel_registry().find(op, DeviceType::cpu, dt);
  if (k == nullptr) throw std::runtime_error(std::string("no kernel for ") + op_name(op));
  return *k;
}

void run_both(OpId op, const std::vector<Pair>& in, const std::vector<Pair>& out,
              const void* params, const char* impl) {
  const KernelInfo& ours = kernel(op, DType::f32);
  ASSERT_STREQ(ours.impl, impl) << op_name(op);
  KernelArgs a64, a32;
  for (const Pair& p : in) a64.in.push_back(p.t64), a32.in.push_back(p.t32);
  for (const Pair& p : out) a64.out.push_back(p.t64), a32.out.push_back(p.t32);
  a64.params = a32.params = params;
  kernel(op, DType::f64).fn(a64);
  ours.fn(a32);
}

void expect_close(const Pair& p, double tol, const std::string& what) {
  ASSERT_TRUE(p.t32.defined()) << what;
  const std::vector<double> ref = p.t64.to_vector();
  const std::vector<double> got = p.t32.to_vector();
  ASSERT_EQ(ref.size(), got.size()) << what;
  double scale = 1e-3, worst = 0.0;
  size_t worst_at = 0;
  for (double r : ref) {
    if (std::isfinite(r)) scale = std::max(scale, std::abs(r));
  }
  for (size_t i = 0; i < ref.size(); ++i) {
    // An infinite reference (max pooling over an empty window) must be matched exactly.
    const double err = got[i] == ref[i] ? 0.0
                       : std::isfinite(got[i]) && std::isfinite(ref[i])
                           ? std::abs(got[i] - ref[i])
                           : std::numeric_limits<double>::infinity();
    if (err > worst) worst = err, worst_at = i;
  }
  EXPECT_LE(worst, tol * scale) << what << ": worst element " << worst_at << " got "
                                << got[worst_at] << " want " << ref[worst_at] << " (scale " << scale
                                << ")";
}

double sum_tolerance(int64_t reduction) {
  return 1e-4 * std::sqrt(std::max(1.0, static_cast<double>(reduction) / 256.0));
}

}  // namespace cvd::kernel_pair_test
