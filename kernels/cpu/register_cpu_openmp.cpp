// The hand-written OpenMP f32 kernels of the CPU backend.
#include "kernels/cpu/cpu_kernels.h"
#include "kernels/cpu/cpu_openmp_families.h"

namespace cvd {

void register_cpu_openmp_kernels(KernelRegistry& r) {
  cpu::register_pointwise_kernels(r);
  cpu::register_broadcast_kernels(r);
  cpu::register_reduce_kernels(r);
  cpu::register_layout_kernels(r);
  cpu::register_resize_kernels(r);
  cpu::register_grid_sample_kernels(r);
  cpu::register_optimizer_kernels(r);
  cpu::register_row_kernels(r);
  cpu::register_batch_norm_kernels(r);
}

}  // namespace cvd
