// Registers the resampling CUDA kernels (bodies in kernels/cuda/resample_body.h).
#include "kernels/cuda/device_launch.cuh"
#include "kernels/cuda/resample_body.h"

namespace cvd::cuda {

void register_cuda_resample(KernelRegistry& r) {
  CVD_REGISTER_CUDA(r, upsample_bilinear2d, f32, upsample_bilinear2d_op);
  CVD_REGISTER_CUDA(r, upsample_bilinear2d_backward, f32, upsample_bilinear2d_backward_op);
  CVD_REGISTER_CUDA(r, upsample_nearest2d, f32, upsample_nearest2d_op);
  CVD_REGISTER_CUDA(r, upsample_nearest2d_backward, f32, upsample_nearest2d_backward_op);
  CVD_REGISTER_CUDA(r, upsample_bicubic2d, f32, upsample_bicubic2d_op);
  CVD_REGISTER_CUDA(r, upsample_bicubic2d_backward, f32, upsample_bicubic2d_backward_op);
  CVD_REGISTER_CUDA(r, grid_sample, f32, grid_sample_op);
  CVD_REGISTER_CUDA(r, grid_sample_backward, f32, grid_sample_backward_op);
}

}  // namespace cvd::cuda
