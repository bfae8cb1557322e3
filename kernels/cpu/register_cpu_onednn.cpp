// The oneDNN-backed f32 kernels of the CPU backend.
#include "kernels/cpu/cpu_kernels.h"
#include "kernels/cpu/onednn_kernels.h"

namespace cvd {

void register_cpu_onednn_kernels(KernelRegistry& r) {
  onednn::register_conv_kernels(r);
  onednn::register_deconv_kernels(r);
  onednn::register_pool_kernels(r);
  onednn::register_matmul_kernels(r);
}

}  // namespace cvd
