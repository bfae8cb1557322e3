// CUDA runtime glue: device discovery, the device allocator, host<->device copies. Without a
// GPU (or driver) at run time every query reports zero devices and CUDA requests fail clearly.
#include <cuda_runtime.h>

#include <mutex>
#include <string>

#include "engine/backend_info.h"
#include "engine/dispatch.h"

namespace cvd {

namespace {

struct CudaState {
  int count = 0;
  std::string status;
};

const CudaState& cuda_state() {
  static CudaState s;
  static std::once_flag once;
  std::call_once(once, [] {
    int n = 0;
    cudaError_t e = cudaGetDeviceCount(&n);
    if (e != cudaSuccess) {
      s.count = 0;
      s.status = std::string("no usable GPU: ") + cudaGetErrorString(e);
      cudaGetLastError();
    } else {
      s.count = n;
      s.status = std::to_string(n) + " device(s)";
    }
  });
  return s;
}

void check(cudaError_t e, const char* what) {
  if (e != cudaSuccess) fail(ErrorCategory::device, "CUDA {} failed: {}", what, cudaGetErrorString(e));
}

class CudaAllocator final : public Allocator {
 public:
  void* allocate(size_t nbytes) override {
    if (nbytes == 0) return nullptr;
    if (cuda_state().count == 0)
      fail(ErrorCategory::device, "CUDA tensor requested but {}", cuda_state().status);
    void* p = nullptr;
    check(cudaMalloc(&p, nbytes), "cudaMalloc");
    return p;
  }
  void deallocate(void* p, size_t) override {
    if (p) cudaFree(p);
  }
  Device device() const override { return Device::cuda(0); }
};

}  // namespace

int cuda_device_count() { return cuda_state().count; }
std::string cuda_runtime_status() { return cuda_state().status; }

Tensor device_copy(const Tensor& x, Device d) {
  CVD_CHECK(x.is_contiguous(), "device_copy needs a contiguous tensor, got {}", x.str());
  if (d.is_cuda() && cuda_state().count == 0)
    fail(ErrorCategory::device, "cannot copy {} to {}: {}", x.str(), d.str(), cuda_state().status);
  Tensor y = Tensor::empty(x.shape(), x.dtype(), d);
  cudaMemcpyKind kind = x.device().is_cpu() ? (d.is_cpu() ? cudaMemcpyHostToHost : cudaMemcpyHostToDevice)
                                            : (d.is_cpu() ? cudaMemcpyDeviceToHost : cudaMemcpyDeviceToDevice);
  check(cudaMemcpy(y.data_ptr(), x.data_ptr(), x.nbytes(), kind), "cudaMemcpy");
  return y;
}

void register_cuda_kernels(KernelRegistry&) {
  static CudaAllocator alloc;
  set_device_allocator(DeviceType::cuda, &alloc);
}

}  // namespace cvd
