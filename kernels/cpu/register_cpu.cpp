// The CPU f32 backend: every (op, cpu, f32) kernel of the dispatch table.
#include <oneapi/dnnl/dnnl.hpp>
#include <string>

#include "kernels/cpu/cpu_backend.h"
#include "kernels/cpu/cpu_kernels.h"
#include "kernels/cpu/onednn_context.h"

namespace cvd {

namespace cpu {
void register_correlation_kernels(KernelRegistry& r);  // cpu_correlation.cpp
}  // namespace cpu

namespace {

void register_cpu_kernels(KernelRegistry& r) {
  register_cpu_openmp_kernels(r);
  register_cpu_onednn_kernels(r);
  cpu::register_correlation_kernels(r);
}

std::string describe() {
  const dnnl_version_t* v = dnnl_version();
  return "cpu (f32; oneDNN " + std::to_string(v->major) + "." + std::to_string(v->minor) + "." +
         std::to_string(v->patch) + ", OpenMP)";
}

}  // namespace

BackendHooks cpu_backend() {
  BackendHooks b;
  b.name = "cpu";
  b.description = describe();
  b.register_kernels = &register_cpu_kernels;
  b.bf16_supported = &onednn::bf16_supported;
  b.bf16_unit = &onednn::bf16_unit;
  return b;
}

}  // namespace cvd
