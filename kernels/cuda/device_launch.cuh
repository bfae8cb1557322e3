// Device side of the kernel-body scheme of kernels/cuda/launch_body.h: the stream every CUDA
// kernel of the engine runs on, error checks, and DeviceLaunch, which runs a body with one
// thread per flat index (grid-stride loop). Included by the .cu files only.
#pragma once
#include <cuda_runtime.h>

#include <cstdint>

#include "engine/dispatch.h"
#include "engine/error.h"

namespace cvd::cuda {

// The one stream of the engine (created on first use, non-blocking). All CUDA kernels, cuBLAS
// calls and host<->device copies of the process are issued on it, so they run in program order
// and the caching allocator may reuse a freed block at once. (The engine has no per-context
// state yet; one global stream is the documented choice.)
cudaStream_t engine_stream();

// Throws Error(device) naming `what` when e is not cudaSuccess.
void check_cuda(cudaError_t e, const char* what);

// Registration of each op family (kernels/cuda/cuda_<family>.cu).
void register_cuda_pointwise(KernelRegistry& r);
void register_cuda_layout(KernelRegistry& r);
void register_cuda_resample(KernelRegistry& r);
void register_cuda_norm_pool(KernelRegistry& r);
void register_cuda_conv(KernelRegistry& r);
void register_cuda_matmul(KernelRegistry& r);
void register_cuda_correlation(KernelRegistry& r);
void register_cuda_rows(KernelRegistry& r);

template <class Body>
__global__ void run_body_kernel(int64_t n, Body body) {
  const int64_t step = static_cast<int64_t>(gridDim.x) * blockDim.x;
  for (int64_t i = static_cast<int64_t>(blockIdx.x) * blockDim.x + threadIdx.x; i < n; i += step)
    body(i);
}

struct DeviceLaunch {
  static constexpr int kThreads = 256;
  template <class Body>
  static void launch(int64_t n, const Body& body) {
    if (n <= 0) return;
    int64_t blocks = (n + kThreads - 1) / kThreads;
    if (blocks > (int64_t{1} << 20)) blocks = int64_t{1} << 20;
    run_body_kernel<Body><<<static_cast<unsigned>(blocks), kThreads, 0, engine_stream()>>>(n, body);
    check_cuda(cudaGetLastError(), "kernel launch");
  }
};

}  // namespace cvd::cuda

// Registers `driver<DeviceLaunch>` (a `template <class Launch> void driver(const KernelArgs&)`)
// as the (op, cuda, dtype) kernel.
#define CVD_REGISTER_CUDA(registry, op, dtype, driver)               \
  (registry).add(                                                    \
      ::cvd::OpId::op, ::cvd::DeviceType::cuda, ::cvd::DType::dtype, \
      [](const ::cvd::KernelArgs& a) { driver<::cvd::cuda::DeviceLaunch>(a); }, "cuda")
