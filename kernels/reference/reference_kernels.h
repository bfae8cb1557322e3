// The float64 reference kernels (the oracle every fast kernel is checked against): plain loops in
// double, written for clarity rather than speed. Registered for (op, cpu, f64) by
// register_reference_kernels (register_reference.cpp). The kernel contract is in engine/dispatch.h
// and the per-op semantics in engine/kernel_params.h.
#pragma once
#include <cstdint>

#include "engine/dispatch.h"

namespace cvd::reference {

// ---- Tensor plumbing (reference_tensor.cpp) ----------------------------------------------------
void copy(const KernelArgs& a);
void fill(const KernelArgs& a);
void reduce_sum(const KernelArgs& a);
void concat(const KernelArgs& a);
void pad(const KernelArgs& a);
void matmul(const KernelArgs& a);

// ---- Element-wise (reference_pointwise.cpp) ----------------------------------------------------
void unary(const KernelArgs& a);
void unary_backward(const KernelArgs& a);
void binary(const KernelArgs& a);
void where(const KernelArgs& a);

// ---- Convolutions (reference_conv.cpp) ---------------------------------------------------------
void conv2d(const KernelArgs& a);
void conv2d_backward_data(const KernelArgs& a);
void conv2d_backward_weight(const KernelArgs& a);
void conv_transpose2d(const KernelArgs& a);
void conv_transpose2d_backward_data(const KernelArgs& a);
void conv_transpose2d_backward_weight(const KernelArgs& a);

// ---- Normalisation and pooling (reference_norm_pool.cpp) ---------------------------------------
void batch_norm(const KernelArgs& a);
void batch_norm_backward(const KernelArgs& a);
void max_pool2d(const KernelArgs& a);
void max_pool2d_backward(const KernelArgs& a);
void avg_pool2d(const KernelArgs& a);
void avg_pool2d_backward(const KernelArgs& a);

// ---- Row normalisations over the last dimension (reference_rows.cpp) ----------------------------
void layer_norm(const KernelArgs& a);
void layer_norm_backward(const KernelArgs& a);
void softmax(const KernelArgs& a);
void softmax_backward(const KernelArgs& a);

// ---- Resampling (reference_resample.cpp) -------------------------------------------------------
void upsample_bilinear2d(const KernelArgs& a);
void upsample_bilinear2d_backward(const KernelArgs& a);
void upsample_nearest2d(const KernelArgs& a);
void upsample_nearest2d_backward(const KernelArgs& a);
void upsample_bicubic2d(const KernelArgs& a);
void upsample_bicubic2d_backward(const KernelArgs& a);
void grid_sample(const KernelArgs& a);
void grid_sample_backward(const KernelArgs& a);

// ---- Optical flow (reference_correlation.cpp) --------------------------------------------------
void correlation(const KernelArgs& a);
void correlation_backward(const KernelArgs& a);
void channel_norm(const KernelArgs& a);
void channel_norm_backward(const KernelArgs& a);

// ---- Optimiser steps (reference_optim.cpp) -----------------------------------------------------
void adam_update(const KernelArgs& a);
void sgd_update(const KernelArgs& a);

}  // namespace cvd::reference
