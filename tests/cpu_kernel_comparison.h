// Helpers of the fast-kernel tests: run one op's f32 CPU kernel and its float64 reference
// kernel through the dispatch registry on the same inputs, and compare the outputs.
// Input values are rounded to f32 first, so both kernels see identical numbers and only the
// arithmetic differs. Outputs are pre-filled with NaN, so an element a kernel forgets to write
// fails the comparison.
#pragma once
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "engine/dispatch.h"
#include "engine/random.h"
#include "engine/tensor.h"

namespace cvd::test {

// One tensor twice: f64 for the reference kernel, f32 for the fast kernel, equal values.
struct Pair {
  Tensor t64, t32;
};

inline Pair pair_of(std::vector<double> values, const Shape& shape) {
  for (double& v : values) v = static_cast<double>(static_cast<float>(v));
  return {Tensor::from_vector(values, shape, DType::f64),
          Tensor::from_vector(values, shape, DType::f32)};
}

inline Pair normal(const Shape& shape, Generator& gen, double std = 1.0) {
  std::vector<double> v(static_cast<size_t>(shape_numel(shape)));
  for (double& x : v) x = std * gen.normal();
  return pair_of(v, shape);
}

inline Pair uniform(const Shape& shape, Generator& gen, double lo, double hi) {
  std::vector<double> v(static_cast<size_t>(shape_numel(shape)));
  for (double& x : v) x = lo + (hi - lo) * gen.uniform();
  return pair_of(v, shape);
}

inline Pair integers(const Shape& shape, Generator& gen, int64_t lo, int64_t hi) {
  std::vector<double> v(static_cast<size_t>(shape_numel(shape)));
  for (double& x : v) x = static_cast<double>(gen.randint(lo, hi));
  return pair_of(v, shape);
}

// A strided view (shape, strides, offset in elements) of one tensor's storage.
inline Tensor strided_view(const Tensor& base, const Shape& shape, const Shape& strides,
                           int64_t offset) {
  auto impl = std::make_shared<TensorImpl>();
  impl->storage = base.storage();
  impl->shape = shape;
  impl->strides = strides;
  impl->offset = base.offset() + offset;
  impl->dtype = base.dtype();
  return Tensor(std::move(impl));
}

inline Pair view(const Pair& p, const Shape& shape, const Shape& strides, int64_t offset = 0) {
  return {strided_view(p.t64, shape, strides, offset), strided_view(p.t32, shape, strides, offset)};
}

// `base` broadcast to `shape` (numpy rules: base's dims align with the trailing dims).
inline Pair broadcast(const Pair& base, const Shape& shape) {
  const Shape& bs = base.t64.shape();
  const Shape bst = contiguous_strides(bs);
  Shape strides(shape.size(), 0);
  const size_t lead = shape.size() - bs.size();
  for (size_t d = 0; d < bs.size(); ++d) strides[lead + d] = bs[d] == 1 ? 0 : bst[d];
  return view(base, shape, strides);
}

// Tensor of `shape` whose dims are stored in the order `perm` (a non-contiguous view).
inline Pair permuted(const Shape& shape, const std::vector<int>& perm, Generator& gen) {
  Shape stored(shape.size());
  for (size_t i = 0; i < perm.size(); ++i) stored[i] = shape[perm[i]];
  const Pair base = normal(stored, gen);
  const Shape st = contiguous_strides(stored);
  Shape strides(shape.size());
  for (size_t i = 0; i < perm.size(); ++i) strides[perm[i]] = st[i];
  return view(base, shape, strides);
}

inline std::vector<double> values_of(const Tensor& t) {
  std::vector<double> v(static_cast<size_t>(t.numel()));
  if (t.dtype() == DType::f64) {
    const double* p = t.data<double>();
    for (size_t i = 0; i < v.size(); ++i) v[i] = p[i];
  } else {
    const float* p = t.data<float>();
    for (size_t i = 0; i < v.size(); ++i) v[i] = p[i];
  }
  return v;
}

inline Tensor nan_filled(const Shape& shape, DType dtype) {
  Tensor t = Tensor::empty(shape, dtype);
  if (dtype == DType::f64) {
    double* p = t.data<double>();
    for (int64_t i = 0; i < t.numel(); ++i) p[i] = std::numeric_limits<double>::quiet_NaN();
  } else {
    float* p = t.data<float>();
    for (int64_t i = 0; i < t.numel(); ++i) p[i] = std::numeric_limits<float>::quiet_NaN();
  }
  return t;
}

// Runs op on both backends; returns {fast, reference} values of every output (and, for the
// in-place optimiser ops, of every input), as double.
struct Results {
  std::vector<std::vector<double>> fast, ref;
};

inline Results run_both(OpId op, const std::vector<Pair>& in, const std::vector<Shape>& out_shapes,
                        const void* params, bool read_inputs = false,
                        DType fast_out_dtype = DType::f32) {
  const KernelInfo* fast = kernel_registry().find(op, DeviceType::cpu, DType::f32);
  const KernelInfo* ref = kernel_registry().find(op, DeviceType::cpu, DType::f64);
  EXPECT_TRUE(fast != nullptr && ref != nullptr) << op_name(op);
  if (!fast || !ref) return {};
  EXPECT_STREQ(fast->impl, "openmp") << op_name(op);
  KernelArgs a32, a64;
  a32.params = a64.params = params;
  for (const Pair& p : in) {
    a32.in.push_back(p.t32);
    a64.in.push_back(p.t64);
  }
  for (const Shape& s : out_shapes) {
    a32.out.push_back(nan_filled(s, fast_out_dtype));
    a64.out.push_back(nan_filled(s, DType::f64));
  }
  fast->fn(a32);
  ref->fn(a64);
  Results r;
  for (size_t i = 0; i < out_shapes.size(); ++i) {
    r.fast.push_back(values_of(a32.out[i]));
    r.ref.push_back(values_of(a64.out[i]));
  }
  if (read_inputs) {
    for (size_t i = 0; i < in.size(); ++i) {
      if (!in[i].t64.defined()) continue;
      r.fast.push_back(values_of(a32.in[i]));
      r.ref.push_back(values_of(a64.in[i]));
    }
  }
  return r;
}

// max |fast - ref| <= tol * max |ref|, per output; NaN anywhere fails.
inline void expect_close(const Results& r, double tol, const std::string& what) {
  ASSERT_EQ(r.fast.size(), r.ref.size()) << what;
  for (size_t k = 0; k < r.fast.size(); ++k) {
    const std::vector<double>& f = r.fast[k];
    const std::vector<double>& g = r.ref[k];
    ASSERT_EQ(f.size(), g.size()) << what << " output " << k;
    double scale = 0.0;
    for (double v : g) scale = std::max(scale, std::abs(v));
    const double bound = tol * std::max(scale, 1e-30);
    int64_t bad = 0, first = -1;
    for (size_t i = 0; i < f.size(); ++i) {
      if (!(std::abs(f[i] - g[i]) <= bound)) {
        if (first < 0) first = static_cast<int64_t>(i);
        ++bad;
      }
    }
    EXPECT_EQ(bad, 0) << what << " output " << k << ": " << bad << " of " << f.size()
                      << " elements off by more than " << bound << "; first at " << first
                      << ": fast " << (first >= 0 ? f[first] : 0.0) << " ref "
                      << (first >= 0 ? g[first] : 0.0);
  }
}

inline std::string shape_text(const Shape& s) { return shape_str(s); }

}  // namespace cvd::test
