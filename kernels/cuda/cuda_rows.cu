// Registers the row-normalisation CUDA kernels (bodies in kernels/cuda/rows_body.h).
#include "kernels/cuda/device_launch.cuh"
#include "kernels/cuda/rows_body.h"

namespace cvd::cuda {

void register_cuda_rows(KernelRegistry& r) {
  CVD_REGISTER_CUDA(r, layer_norm, f32, layer_norm_op);
  CVD_REGISTER_CUDA(r, layer_norm_backward, f32, layer_norm_backward_op);
  CVD_REGISTER_CUDA(r, softmax, f32, softmax_op);
  CVD_REGISTER_CUDA(r, softmax_backward, f32, softmax_backward_op);
}

}  // namespace cvd::cuda
