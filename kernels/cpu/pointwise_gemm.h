// Hand-written AVX-512 product for pointwise (1x1) convolutions on NCHW tensors: per image n,
//   C_n [M, P] = A [M, K] x B_n [K, P] (+ bias [M]),
// with B_n and C_n the image's channel planes (row pitch P: pixels) and A the weights, read through
// strides so that the backward-data pass uses W^T [C, O] without a copy.
//
// Why it exists: on large images (Mannequin's full resolution, 224x384 with 128 -> 64 channels)
// oneDNN 2.6's sgemm and matmul primitive ran these products at about half the speed of oneDNN's
// blocked 1x1 convolution on data already in its layout (bench/bench_conv.cpp), and that layout
// costs a reorder each way on our NCHW tensors. Here a strip of pixels of B is copied into a
// contiguous block (the plane pitch would otherwise put every channel row into the same L1 sets),
// the next strip is prefetched while the current one is multiplied, and a register tile of 6 rows
// of A x 64 pixels accumulates in 24 vector registers.
//
// Each output element sums over k in increasing order in one f32 accumulator (blocks of kKBlock
// channels in turn), whatever the thread count: the result is deterministic.
#pragma once
#include <cstdint>

namespace cvd::cpu {

// True when the CPU runs the kernel (AVX-512F) and it was compiled in (x86-64 GCC or Clang).
bool pointwise_gemm_supported();

struct PointwiseGemm {
  int64_t n = 0, m = 0, k = 0, p = 0;  // images, rows of A and C, inner size, pixels per image
  const float* a = nullptr;            // A (m, k) at a[m * a_row + k * a_col]
  int64_t a_row = 0, a_col = 1;
  const float* b = nullptr;     // B_n (k, p) at b[(n * k + k) * p + p]
  const float* bias = nullptr;  // [m] or null
  float* c = nullptr;           // C_n (m, p) at c[(n * m + m) * p + p]
};

// Computes the product; only call when pointwise_gemm_supported().
void pointwise_gemm(const PointwiseGemm& g);

}  // namespace cvd::cpu
