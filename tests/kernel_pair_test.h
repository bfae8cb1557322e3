// The harness of the CPU kernel tests against the float64 reference kernels (test_onednn_conv.cpp,
// test_onednn_kernels.cpp): the oneDNN-backed and hand-written f32 kernels and the float64
// reference kernels (kernels/reference), both called through the dispatch registry on the same
// inputs. Inputs are rounded to f32 first, so both kernels see identical numbers and only the
// arithmetic differs. Outputs are pre-filled with NaN, so an element a kernel forgets to write
// fails.
//
// Tolerances, as max |ours - ref| <= tol * max(max finite |ref|, 1e-3) over each output (an
// infinite reference must be matched exactly):
//   conv / deconv forward and backward data, batch norm, matmul: 1e-4;
//   conv / deconv backward weight and bias (sums over N * OH * OW products): 1e-4 scaled by
//     sqrt(max(1, reduction / 256)) (the random-walk growth of f32 rounding in long sums);
//   pooling: 1e-5 (max pooling is exact; averages are short sums).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "engine/dispatch.h"
#include "engine/random.h"
#include "engine/tensor.h"

namespace cvd::kernel_pair_test {

// One tensor twice: f64 for the reference kernel, f32 for ours, equal values.
struct Pair {
  Tensor t64, t32;
};

// `values` rounded to f32, as both tensors.
Pair make_pair(std::vector<double> values, const Shape& shape);
Pair normal(const Shape& shape, Generator& gen, double std = 1.0, double mean = 0.0);
Pair uniform(const Shape& shape, Generator& gen, double lo, double hi);
// Outputs, pre-filled with NaN.
Pair outputs(const Shape& shape);
// An absent (undefined) input or output.
Pair none();

const KernelInfo& kernel(OpId op, DType dt);

// Runs (op, cpu, f64) and (op, cpu, f32) on the two halves of the pairs; the f32 kernel must be
// implementation `impl`.
void run_both(OpId op, const std::vector<Pair>& in, const std::vector<Pair>& out,
              const void* params, const char* impl = "onednn");

// The f32 half within `tol` of the f64 half (the tolerance rule above).
void expect_close(const Pair& p, double tol, const std::string& what);

// The tolerance of a sum over `reduction` products (the rule above).
double sum_tolerance(int64_t reduction);

}  // namespace cvd::kernel_pair_test
