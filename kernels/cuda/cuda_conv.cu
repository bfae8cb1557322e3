// Registers the convolution CUDA kernels (bodies in kernels/cuda/conv_body.h).
#include "kernels/cuda/conv_body.h"
#include "kernels/cuda/device_launch.cuh"

namespace cvd::cuda {

void register_cuda_conv(KernelRegistry& r) {
  CVD_REGISTER_CUDA(r, conv2d, f32, conv2d_op);
  CVD_REGISTER_CUDA(r, conv2d_backward_data, f32, conv2d_backward_data_op);
  CVD_REGISTER_CUDA(r, conv2d_backward_weight, f32, conv2d_backward_weight_op);
  CVD_REGISTER_CUDA(r, conv_transpose2d, f32, conv_transpose2d_op);
  CVD_REGISTER_CUDA(r, conv_transpose2d_backward_data, f32, conv_transpose2d_backward_data_op);
  CVD_REGISTER_CUDA(r, conv_transpose2d_backward_weight, f32, conv_transpose2d_backward_weight_op);
}

}  // namespace cvd::cuda
