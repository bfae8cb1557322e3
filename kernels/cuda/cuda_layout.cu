// Registers the layout CUDA kernels (bodies in kernels/cuda/layout_body.h).
#include "kernels/cuda/device_launch.cuh"
#include "kernels/cuda/layout_body.h"

namespace cvd::cuda {

void register_cuda_layout(KernelRegistry& r) {
  CVD_REGISTER_CUDA(r, reduce_sum, f32, reduce_sum_op);
  CVD_REGISTER_CUDA(r, concat, f32, concat_op);
  CVD_REGISTER_CUDA(r, pad, f32, pad_op);
}

}  // namespace cvd::cuda
