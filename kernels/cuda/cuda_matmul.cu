// Batched matmul on CUDA through cuBLAS (a vendor call: no hand-written body). Row-major
// c = op(a) op(b) is computed as the column-major product c^T = op(b)^T op(a)^T.
#include <cublas_v2.h>

#include <mutex>

#include "engine/kernel_params.h"
#include "kernels/cuda/device_launch.cuh"

namespace cvd::cuda {

namespace {

cublasHandle_t cublas_handle() {
  static cublasHandle_t handle = nullptr;
  static std::once_flag once;
  std::call_once(once, [] {
    if (cublasCreate(&handle) != CUBLAS_STATUS_SUCCESS)
      fail(ErrorCategory::device, "kernels/cuda/cuda_matmul.cu: cublasCreate failed");
    cublasSetStream(handle, engine_stream());
    cublasSetMathMode(handle, CUBLAS_DEFAULT_MATH);  // true f32, no TF32
  });
  return handle;
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
  const cublasStatus_t s = cublasSgemmStridedBatched(
      cublas_handle(), p.trans_b ? CUBLAS_OP_T : CUBLAS_OP_N, p.trans_a ? CUBLAS_OP_T : CUBLAS_OP_N,
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
