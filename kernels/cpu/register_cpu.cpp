// The CPU f32 backend: every (op, cpu, f32) kernel of the dispatch table.
#include "kernels/cpu/cpu_kernels.h"

namespace cvd {

namespace cpu {
void register_correlation_kernels(KernelRegistry& r);  // cpu_correlation.cpp
}  // namespace cpu

void register_cpu_kernels(KernelRegistry& r) {
  register_cpu_openmp_kernels(r);
  register_cpu_onednn_kernels(r);
  cpu::register_correlation_kernels(r);
}

}  // namespace cvd
