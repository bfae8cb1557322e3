// Synchronised batch norm (issue 21): training-mode batch norm whose statistics are taken over
// the inputs of every process of the job (engine/process_group.h). Two-pass statistics (the
// mean, then the centred sum of squares: as exact as the single-process kernel), the fused
// batch-norm kernel for the normalisation, and one recorded backward node with its own
// all-reduce; PyTorch's SyncBatchNorm semantics: the running variance is updated with the
// unbiased variance over all processes' values.
#pragma once
#include "engine/kernel_params.h"
#include "engine/tensor.h"

namespace cvd {

// x [N, C, H, W] (N may differ between processes); gamma / beta [C] or undefined; running
// stats [C] updated in place with p.momentum (undefined: not updated). Every process must call it.
Tensor sync_batch_norm(const Tensor& x, const Tensor& running_mean, const Tensor& running_var,
                       const Tensor& gamma, const Tensor& beta, const BatchNormParams& p);

}  // namespace cvd
