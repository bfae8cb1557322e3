// Registers the correlation and channel-norm CUDA kernels (kernels/cuda/correlation_body.h).
#include "kernels/cuda/correlation_body.h"
#include "kernels/cuda/device_launch.cuh"

namespace cvd::cuda {

void register_cuda_correlation(KernelRegistry& r) {
  CVD_REGISTER_CUDA(r, correlation, f32, correlation_op);
  CVD_REGISTER_CUDA(r, correlation_backward, f32, correlation_backward_op);
  CVD_REGISTER_CUDA(r, channel_norm, f32, channel_norm_op);
  CVD_REGISTER_CUDA(r, channel_norm_backward, f32, channel_norm_backward_op);
}

}  // namespace cvd::cuda
