// Registers the element-wise CUDA kernels (bodies in kernels/cuda/pointwise_body.h).
#include "kernels/cuda/device_launch.cuh"
#include "kernels/cuda/pointwise_body.h"

namespace cvd::cuda {

void register_cuda_pointwise(KernelRegistry& r) {
  CVD_REGISTER_CUDA(r, copy, f32, copy_op);
  CVD_REGISTER_CUDA(r, copy, f64, copy_op);
  CVD_REGISTER_CUDA(r, fill, f32, fill_op);
  CVD_REGISTER_CUDA(r, fill, f64, fill_op);
  CVD_REGISTER_CUDA(r, unary, f32, unary_op);
  CVD_REGISTER_CUDA(r, unary_backward, f32, unary_backward_op);
  CVD_REGISTER_CUDA(r, binary, f32, binary_op);
  CVD_REGISTER_CUDA(r, where, f32, where_op);
  CVD_REGISTER_CUDA(r, adam_update, f32, adam_update_op);
  CVD_REGISTER_CUDA(r, sgd_update, f32, sgd_update_op);
}

}  // namespace cvd::cuda
