// Running one call of the kernel table (tests/kernel_case_table.h) on a backend: the call's
// f32 inputs handed to the backend's kernel of the op and its f64 inputs to the float64
// reference kernel (kernels/reference), both through the dispatch registry, and the outputs
// compared. Input values are rounded to f32 first, so both kernels see identical numbers and only
// the arithmetic differs. Outputs are pre-filled with NaN, so an element a kernel forgets to write
// fails the comparison. Shared by every backend's kernel-table test (tests/test_kernel_table.cpp:
// the CPU; tests/test_cuda_emulated.cpp: the CUDA bodies by emulated launch;
// tests/test_cuda_ops.cpp: a CUDA device).
#pragma once
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

const Shape kUndefined{-1};  // an output shape marking an output that is not requested

// One kernel call: what every backend is handed, and how close it must come to the reference.
struct KernelCall {
  std::string what;  // names the call in a failure
  OpId op;
  std::vector<Pair> in;    // an undefined Pair: an input the call leaves out
  std::vector<Shape> out;  // kUndefined: an output the call does not request
  std::shared_ptr<const void> params;
  double tol = 0;            // max |fast - ref| <= tol * max(max |ref|, min_scale) per output
  bool read_inputs = false;  // in-place ops (optimisers): compare the inputs after the call too
  DType out_dtype = DType::f32;
  // Where an output can cancel to far below its inputs (an optimiser's moment from O(1) values):
  // the inputs' scale, so f32 rounding of the inputs' terms is not judged against the result's.
  double min_scale = 0;
};

// `p` kept alive by the call (params outlive the lambdas that build the calls).
template <typename P>
std::shared_ptr<const void> params_of(const P& p) {
  return std::make_shared<const P>(p);
}

// The reference kernel's outputs for `in` (f64 halves), as double: to build the inputs of a
// backward call from a forward's outputs.
std::vector<std::vector<double>> reference_outputs(OpId op, const std::vector<Pair>& in,
                                                   const std::vector<Shape>& out,
                                                   const void* params);

// The call's kernel arguments: its f64 inputs (reference) or f32 inputs on `device` (their
// views kept: the whole storage is copied), NaN-filled outputs there; the params are the call's.
KernelArgs kernel_args(const KernelCall& call, bool reference, DeviceId device);

// Where a backend's kernels live: its kernels in the registry, and the device its tensors are on.
struct KernelBackend {
  std::string name;
  DeviceType type = DeviceType::cpu;
  DeviceId device = DeviceId::cpu();
  // The registry's impl name its kernels carry ("" = any impl but the reference's).
  std::string impl;
};

// Runs `call` on `backend` (its inputs and NaN-filled outputs copied to the backend's device,
// views kept) and on the reference. Returns an empty string when every output agrees, otherwise
// a message naming the call: the first mismatching element and how many there are, or a missing
// kernel (none of the op for the backend, or one of another impl).
std::string compare_call_with_reference(const KernelCall& call, const KernelBackend& backend);

inline std::string shape_text(const Shape& s) { return shape_str(s); }

}  // namespace cvd::test
