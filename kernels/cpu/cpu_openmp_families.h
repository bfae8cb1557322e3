// Per-family registration of the hand-written OpenMP f32 kernels; register_cpu_openmp_kernels
// (register_cpu_openmp.cpp) calls them all.
#pragma once
#include "engine/dispatch.h"
#include "engine/tensor.h"

namespace cvd::cpu {

// Whether t is a defined, contiguous f32 tensor on the CPU (the fast paths' precondition).
inline bool is_cpu_f32_contiguous(const Tensor& t) {
  return t.defined() && t.device().is_cpu() && t.dtype() == DType::f32 && t.is_contiguous();
}

void register_pointwise_kernels(KernelRegistry& r);    // cpu_pointwise.cpp
void register_broadcast_kernels(KernelRegistry& r);    // cpu_broadcast.cpp
void register_reduce_kernels(KernelRegistry& r);       // cpu_reduce.cpp
void register_layout_kernels(KernelRegistry& r);       // cpu_layout.cpp
void register_resize_kernels(KernelRegistry& r);       // cpu_resize.cpp
void register_grid_sample_kernels(KernelRegistry& r);  // cpu_grid_sample.cpp
void register_optimizer_kernels(KernelRegistry& r);    // cpu_optim.cpp
void register_row_kernels(KernelRegistry& r);          // cpu_rows.cpp
void register_batch_norm_kernels(KernelRegistry& r);   // cpu_batch_norm.cpp

}  // namespace cvd::cpu
