// Built when the CUDA toolkit is absent: the CUDA backend registers no kernels and reports no
// devices; asking for a CUDA tensor is a clear Error(unsupported).
#include "engine/error.h"
#include "kernels/cuda/cuda_backend.h"

namespace cvd {

namespace {

void register_no_kernels(KernelRegistry&) {}

int no_devices() { return 0; }

std::string not_compiled() { return "not compiled in (no nvcc at build time)"; }

Tensor refuse_copy(const Tensor& x, DeviceId d) {
  fail(ErrorCategory::unsupported, "cannot copy {} to {}: this build has no CUDA backend", x.str(),
       d.str());
}

}  // namespace

BackendHooks cuda_backend() {
  BackendHooks b;
  b.name = "cuda";
  b.description = "cuda: not compiled in";
  b.register_kernels = &register_no_kernels;
  b.device = DeviceType::cuda;
  b.device_copy = &refuse_copy;
  b.device_count = &no_devices;
  b.runtime_status = &not_compiled;
  return b;
}

}  // namespace cvd
