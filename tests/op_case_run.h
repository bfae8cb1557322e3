// Running one case of the op table (tests/op_case_table.h) on a backend: its inputs drawn as the
// case says, and the comparison of a device's f32 kernels against the float64 reference
// (forward, and the gradient of sum(out * R) for a fixed random R). Shared by every backend's
// table test (tests/test_ops.cpp: CPU; tests/test_cuda_ops.cpp: CUDA) and the table's perf mode
// (bench/op_table_perf.cpp), so each op case is written once and runs everywhere.
#pragma once
#include <string>
#include <vector>

#include "engine/random.h"
#include "tests/op_case_table.h"

namespace cvd::test {

// The largest |x| (0 for none): the scale of the comparisons' tolerances.
double max_abs(const std::vector<double>& v);

// An input as the case specifies it: f64 on the CPU.
Tensor make_case_input(const InputSpec& s, Generator& g);

// The case's f64 inputs from `seed` (differentiable ones requiring grad).
std::vector<Tensor> make_case_inputs(const OpCase& c, uint64_t seed);

// How a comparison runs the fast side.
struct CompareOptions {
  // The f32 inputs as non-contiguous views: rank >= 2 stored with their last two dims swapped
  // (a transposed view), rank 1 the first elements of a longer row (a narrowed view).
  bool strided_inputs = false;
  // The tolerance is max(c.f32_tol, this) (e.g. bf16 arithmetic).
  double min_tol = 0;
};

// Runs the case in f32 on `device` and in f64 on the reference kernels from the same inputs:
// outputs within c.f32_tol * max(1, |ref|max), input gradients within 4x that. Returns the first
// mismatch as a message naming the case, or an empty string when everything agrees.
std::string compare_with_reference(const OpCase& c, DeviceId device, uint64_t seed,
                                   const CompareOptions& options = {});

// The f32 output of the case on `device` from the inputs of `seed` (no gradients).
std::vector<double> run_case_f32(const OpCase& c, DeviceId device, uint64_t seed);

}  // namespace cvd::test
