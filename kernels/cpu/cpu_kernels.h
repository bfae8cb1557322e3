// Registration entry points of the CPU (f32) backend. register_cpu_kernels (register_cpu.cpp)
// calls both: the hand-written OpenMP kernels and the oneDNN-backed ones.
#pragma once
#include "engine/dispatch.h"

namespace cvd {

// kernels/cpu/cpu_*.cpp: copy, fill, unary(_backward), binary, where, reduce_sum, concat, pad,
// bilinear / nearest resize (+ backward), grid_sample (+ backward), adam_update, sgd_update.
void register_cpu_openmp_kernels(KernelRegistry& r);

// The oneDNN-backed kernels: convolutions, deconvolutions, batch norm, pooling, matmul.
void register_cpu_onednn_kernels(KernelRegistry& r);

}  // namespace cvd
