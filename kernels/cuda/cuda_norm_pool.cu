// Registers the batch-norm and pooling CUDA kernels (bodies in kernels/cuda/norm_pool_body.h).
#include "kernels/cuda/device_launch.cuh"
#include "kernels/cuda/norm_pool_body.h"

namespace cvd::cuda {

void register_cuda_norm_pool(KernelRegistry& r) {
  CVD_REGISTER_CUDA(r, batch_norm, f32, batch_norm_op);
  CVD_REGISTER_CUDA(r, batch_norm_backward, f32, batch_norm_backward_op);
  CVD_REGISTER_CUDA(r, max_pool2d, f32, max_pool2d_op);
  CVD_REGISTER_CUDA(r, max_pool2d_backward, f32, max_pool2d_backward_op);
  CVD_REGISTER_CUDA(r, avg_pool2d, f32, avg_pool2d_op);
  CVD_REGISTER_CUDA(r, avg_pool2d_backward, f32, avg_pool2d_backward_op);
}

}  // namespace cvd::cuda
