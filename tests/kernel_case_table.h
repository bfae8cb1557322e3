// The kernel table: every kernel of the dispatch table called directly (below autograd) with
// the shapes, layouts and parameters where its fast paths differ (edge sizes, broadcasts,
// strided inputs, chunked and threaded reductions), grouped in one case per op family. Every
// backend runs every call against the float64 reference kernels (tests/kernel_case_run.h):
// tests/test_kernel_table.cpp (CPU f32), tests/test_cuda_emulated.cpp (the CUDA kernel bodies by
// emulated launch), tests/test_cuda_ops.cpp (a CUDA device). The op table
// (tests/op_case_table.h) is the same idea one level up: ops through autograd, with gradients.
#pragma once
#include <functional>
#include <ostream>
#include <string>
#include <vector>

#include "tests/kernel_case_run.h"

namespace cvd::test {

struct KernelCase {
  std::string name;  // the op family, a valid gtest name
  // The calls, drawn from a fixed seed (the same on every backend and every run).
  std::function<std::vector<KernelCall>()> calls;
};

// gtest prints a case by its name.
inline void PrintTo(const KernelCase& c, std::ostream* os) { *os << c.name; }

// Copy, fill, unary, binary, where, reductions, concat, pad, optimisers, layer norm, softmax,
// matmul.
std::vector<KernelCase> elementwise_kernel_cases();
// Resizes, grid_sample, batch norm, pooling, convolutions, correlation, channel norm.
std::vector<KernelCase> spatial_kernel_cases();
// Both lists.
std::vector<KernelCase> all_kernel_cases();

}  // namespace cvd::test
