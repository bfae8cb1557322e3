// Link shim for the fuzz targets whose readers build tensors (.cvdw, ONNX): they need the tensor
// engine (engine/*.cpp) but none of the compute kernels, so the kernel registries stay empty and
// a cross-device copy is refused. This keeps the sanitized fuzz binaries small and quick to build.
// The readers only allocate CPU tensors and copy bytes into them; none dispatches an op.
#include "engine/backend_info.h"
#include "engine/compute_precision.h"
#include "engine/dispatch.h"
#include "engine/error.h"

namespace cvd {

void register_reference_kernels(KernelRegistry&) {}
void register_cpu_kernels(KernelRegistry&) {}
void register_cuda_kernels(KernelRegistry&) {}

// engine/compute_precision.cpp asks the oneDNN backend (kernels/cpu/onednn_context.cpp) for bf16.
std::string bf16_unit() { return "none"; }
bool bf16_supported(std::string* why) {
  if (why) *why = "fuzz build: no oneDNN backend linked";
  return false;
}

Tensor device_copy(const Tensor&, Device) {
  fail(ErrorCategory::unsupported, "fuzz build: no device backends linked");
}

}  // namespace cvd
