// Batched matmul on CUDA through cuBLAS (a vendor call: no hand-written body). Row-major
// c = op(a) op(b) is computed as the column-major product c^T = op(b)^T op(a)^T.
//
// cuBLAS is loaded at its first use (dlopen), not linked: loading libcublas pulls in
// libcublasLt, whose static initialisers cost every process ~0.3 s at start (measured on a
// 2-core AMD EPYC, CUDA 13), including every run on a machine without a GPU.
#include <cublas_v2.h>
#include <dlfcn.h>

#include <mutex>
#include <string>

#include "engine/kernel_params.h"
#include "kernels/cuda/device_launch.cuh"

namespace cvd::cuda {

namespace {

// The four cuBLAS entry points used here, resolved from the library of the toolkit's major version.
struct Cublas {
  decltype(&cublasCreate_v2) create = nullptr;
  decltype(&cublasSetStream_v2) set_stream = nullptr;
  decltype(&cublasSetMathMode) set_math_mode = nullptr;
  decltype(&cublasSgemmStridedBatched) sgemm_strided_batched = nullptr;
  cublasHandle_t handle = nullptr;
};

template <class F>
void resolve(void* lib, const char* name, F& f) {
  f = reinterpret_cast<F>(dlsym(lib, name));
  if (!f) fail(ErrorCategory::device, "kernels/cuda/cuda_matmul.cu: cuBLAS has no symbol {}", name);
}

const Cublas& cublas() {
  static Cublas c;
  static std::once_flag once;
  std::call_once(once, [] {
    const std::string soname = "libcublas.so." + std::to_string(CUBLAS_VER_MAJOR);
    void* lib = dlopen(soname.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!lib)
      fail(ErrorCategory::device, "kernels/cuda/cuda_matmul.cu: cannot load {} ({})", soname,
           dlerror());
    resolve(lib, "cublasCreate_v2", c.create);
    resolve(lib, "cublasSetStream_v2", c.set_stream);
    resolve(lib, "cublasSetMathMode", c.set_math_mode);
    resolve(lib, "cublasSgemmStridedBatched", c.sgemm_strided_batched);
    if (c.create(&c.handle) != CUBLAS_STATUS_SUCCESS)
      fail(ErrorCategory::device, "kernels/cuda/cuda_matmul.cu: cublasCreate failed");
    c.set_stream(c.handle, engine_stream());
    c.set_math_mode(c.handle, CUBLAS_DEFAULT_MATH);  // true f32, no TF32
  });
  return c;
}

// in {a [B,M,K] (or [B,K,M] if trans_a), b [B or 1,K,N] (or [B or 1,N,K] if trans_b)},
// out {c [B,M,N]}.
void matmul(const KernelArgs& args) {
  const Tensor &a = args.in[0], &b = args.in[1], &c = args.out[0];
  const MatmulParams& p = args.p<MatmulParams>();
  const int64_t batch = c.shape()[0], m = c.shape()[1], n = c.shape()[2];
  const int64_t k = p.trans_a ? a.shape()[1] : a.shape()[2];
  if (c.numel() == 0) return;
  if (k == 0) {
    check_cuda(cudaMemsetAsync(c.data_ptr(), 0, c.nbytes(), engine_stream()), "cudaMemsetAsync");
    return;
  }
  const float one = 1.0f, zero = 0.0f;
  const int ldb = static_cast<int>(p.trans_b ? k : n);
  const int lda = static_cast<int>(p.trans_a ? m : k);
  const long long stride_b = b.shape()[0] == 1 ? 0 : k * n;
  const Cublas& blas = cublas();
  const cublasStatus_t s = blas.sgemm_strided_batched(
      blas.handle, p.trans_b ? CUBLAS_OP_T : CUBLAS_OP_N, p.trans_a ? CUBLAS_OP_T : CUBLAS_OP_N,
      static_cast<int>(n), static_cast<int>(m), static_cast<int>(k), &one, b.data<float>(), ldb,
      stride_b, a.data<float>(), lda, m * k, &zero, c.data<float>(), static_cast<int>(n), m * n,
      static_cast<int>(batch));
  if (s != CUBLAS_STATUS_SUCCESS)
    fail(ErrorCategory::device,
         "kernels/cuda/cuda_matmul.cu: cublasSgemmStridedBatched failed ({})", static_cast<int>(s));
}

}  // namespace

void register_cuda_matmul(KernelRegistry& r) {
  r.add(OpId::matmul, DeviceType::cuda, DType::f32, matmul, "cuda (cuBLAS)");
}

}  // namespace cvd::cuda
