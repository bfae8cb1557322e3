// CUDA runtime glue: device discovery, the caching device allocator, the engine stream,
// host<->device copies and the registration of every CUDA kernel. Without a GPU (or driver) at
// run time every query reports zero devices and CUDA requests fail clearly.
#include <cuda_runtime.h>

#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "engine/dispatch.h"
#include "kernels/cuda/cuda_backend.h"
#include "kernels/cuda/device_launch.cuh"

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
      for (int i = 0; i < n; ++i) {
        cudaDeviceProp prop{};
        if (cudaGetDeviceProperties(&prop, i) == cudaSuccess) {
          s.status += (i == 0 ? ": " : ", ") + std::string(prop.name) + " (sm_" +
                      std::to_string(prop.major) + std::to_string(prop.minor) + ")";
        }
      }
    }
  });
  return s;
}

void require_gpu(const char* what) {
  if (cuda_state().count == 0)
    fail(ErrorCategory::device, "{} needs a CUDA device but there is none: {}", what,
         cuda_state().status);
}

// A caching allocator: freed blocks are kept in per-size free lists (sizes rounded up to 512
// bytes below 1 MiB, to 1 MiB above) and handed out again, so steady-state training does no
// cudaMalloc / cudaFree. All work runs on the one engine stream, so a block freed on the host
// may be reused by the next kernel without synchronisation. When cudaMalloc fails, the cache is
// released and the allocation retried once. Cached blocks live until the process ends.
class CachingCudaAllocator final : public Allocator {
 public:
  void* allocate(size_t nbytes) override {
    if (nbytes == 0) return nullptr;
    require_gpu("allocating a CUDA tensor");
    const size_t size = round_size(nbytes);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      auto it = free_.find(size);
      if (it != free_.end() && !it->second.empty()) {
        void* p = it->second.back();
        it->second.pop_back();
        cached_bytes_ -= size;
        return p;
      }
    }
    void* p = nullptr;
    cudaError_t e = cudaMalloc(&p, size);
    if (e != cudaSuccess) {
      cudaGetLastError();
      release_cache();
      cuda::check_cuda(cudaMalloc(&p, size), "cudaMalloc (after releasing the cache)");
    }
    return p;
  }
  void deallocate(void* p, size_t nbytes) override {
    if (!p) return;
    std::lock_guard<std::mutex> lock(mutex_);
    const size_t size = round_size(nbytes);
    free_[size].push_back(p);
    cached_bytes_ += size;
  }
  DeviceId device() const override { return DeviceId::cuda(0); }

 private:
  static size_t round_size(size_t n) {
    const size_t unit = n < (size_t{1} << 20) ? 512 : (size_t{1} << 20);
    return (n + unit - 1) / unit * unit;
  }
  void release_cache() {
    cudaStreamSynchronize(cuda::engine_stream());
    std::lock_guard<std::mutex> lock(mutex_);
    for (auto& [size, blocks] : free_) {
      for (void* p : blocks) cudaFree(p);
      blocks.clear();
    }
    cached_bytes_ = 0;
  }

  std::mutex mutex_;
  std::map<size_t, std::vector<void*>> free_;
  size_t cached_bytes_ = 0;
};

}  // namespace

namespace cuda {

void check_cuda(cudaError_t e, const char* what) {
  if (e != cudaSuccess) {
    cudaGetLastError();
    fail(ErrorCategory::device, "kernels/cuda: CUDA {} failed: {}", what, cudaGetErrorString(e));
  }
}

cudaStream_t engine_stream() {
  static cudaStream_t stream = nullptr;
  static std::once_flag once;
  std::call_once(once, [] {
    require_gpu("creating the CUDA stream");
    check_cuda(cudaStreamCreateWithFlags(&stream, cudaStreamNonBlocking), "cudaStreamCreate");
  });
  return stream;
}

}  // namespace cuda

namespace {

int device_count() { return cuda_state().count; }
std::string runtime_status() { return cuda_state().status; }

// Copies through the engine stream and waits for it, so the result is complete on return (host
// memory is pageable; the copy is synchronous with respect to the host either way).
Tensor copy_between_devices(const Tensor& x, DeviceId d) {
  CVD_CHECK(x.is_contiguous(), "device_copy needs a contiguous tensor, got {}", x.str());
  if (d.is_cuda() || x.device().is_cuda()) require_gpu("copying a tensor to or from CUDA");
  Tensor y = Tensor::empty(x.shape(), x.dtype(), d);
  if (x.nbytes() == 0) return y;
  const cudaMemcpyKind kind =
      x.device().is_cpu() ? (d.is_cpu() ? cudaMemcpyHostToHost : cudaMemcpyHostToDevice)
                          : (d.is_cpu() ? cudaMemcpyDeviceToHost : cudaMemcpyDeviceToDevice);
  cudaStream_t s = cuda::engine_stream();
  cuda::check_cuda(cudaMemcpyAsync(y.data_ptr(), x.data_ptr(), x.nbytes(), kind, s),
                   "cudaMemcpyAsync");
  cuda::check_cuda(cudaStreamSynchronize(s), "cudaStreamSynchronize after a copy");
  return y;
}

// Registers every CUDA kernel even without a GPU (so coverage is visible everywhere); running one
// then fails at the allocation or stream creation with a clear message.
void register_cuda_kernels(KernelRegistry& r) {
  // Never destroyed: tensors held by other static objects may be freed after main returns.
  static CachingCudaAllocator* alloc = new CachingCudaAllocator();
  set_device_allocator(DeviceType::cuda, alloc);
  cuda::register_cuda_pointwise(r);
  cuda::register_cuda_layout(r);
  cuda::register_cuda_resample(r);
  cuda::register_cuda_norm_pool(r);
  cuda::register_cuda_rows(r);
  cuda::register_cuda_conv(r);
  cuda::register_cuda_matmul(r);
  cuda::register_cuda_correlation(r);
}

}  // namespace

BackendHooks cuda_backend() {
  BackendHooks b;
  b.name = "cuda";
  b.description = "cuda (f32)";
  b.register_kernels = &register_cuda_kernels;
  b.device = DeviceType::cuda;
  b.device_copy = &copy_between_devices;
  b.device_count = &device_count;
  b.runtime_status = &runtime_status;
  return b;
}

}  // namespace cvd
