// Built when the CUDA toolkit is absent: the CUDA backend registers no kernels and reports no
// devices; asking for a CUDA tensor is a clear Error(unsupported).
#include "engine/backend_info.h"
#include "engine/dispatch.h"

namespace cvd {

void register_cuda_kernels(KernelRegistry&) {}

int cuda_device_count() { return 0; }

std::string cuda_runtime_status() { return "not compiled in (no nvcc at build time)"; }

Tensor device_copy(const Tensor& x, Device d) {
  fail(ErrorCategory::unsupported, "cannot copy {} to {}: this build has no CUDA backend", x.str(),
       d.str());
}

}  // namespace cvd
