// Hand-written depthwise 2-D convolution (groups == in channels == out channels) on NCHW planes,
// forward, backward data and backward weights (+ bias), with OpenMP over planes / channels.
//
// Why it exists: a depthwise convolution is memory bound, so oneDNN's blocked (nChw16c) kernels
// lose most of their speed to the NCHW <-> blocked reorders our NCHW tensors need, and oneDNN 2.6
// has no JIT backward-weights kernel for depthwise filters wider than 3 (it falls back to a slow
// GEMM). This kernel reads NCHW directly: each input row is copied once into a zero-padded,
// stride-phase-split buffer, after which every filter tap is a unit-stride loop the compiler
// vectorizes (cloned for AVX-512 / AVX2 / baseline and picked at run time).
#pragma once
#include <cstdint>

namespace cvd::cpu {

struct DepthwiseGeometry {
  int64_t n = 0, c = 0, h = 0, w = 0, oh = 0, ow = 0, kh = 0, kw = 0;
  int64_t stride_h = 1, stride_w = 1, pad_top = 0, pad_left = 0, dil_h = 1, dil_w = 1;
};

// y [n, c, oh, ow] = depthwise(x [n, c, h, w], w [c, 1, kh, kw]) + b[c] (b may be null).
void depthwise_conv2d_forward(const DepthwiseGeometry& g, const float* x, const float* w,
                              const float* b, float* y);

// gx [n, c, h, w] from gy [n, c, oh, ow] and w.
void depthwise_conv2d_backward_data(const DepthwiseGeometry& g, const float* gy, const float* w,
                                    float* gx);

// gw [c, 1, kh, kw] (and gb [c] when not null) from gy and x.
void depthwise_conv2d_backward_weight(const DepthwiseGeometry& g, const float* gy, const float* x,
                                      float* gw, float* gb);

// Which implementation serves the channels (a test and benchmark hook; `automatic` is the default
// and what the library uses):
//   automatic       the fastest measured: on AVX-512, direct for forward and backward data at
//                   unit stride, blocked otherwise; portable without AVX-512;
//   portable        every pass on the portable implementation;
//   blocked_avx512  every pass on the channel-interleaved AVX-512 implementation (channels in
//                   whole vectors of 16; the rest portable);
//   direct_avx512   forward and backward data on the AVX-512 NCHW implementation at every stride,
//                   backward weights blocked.
// The AVX-512 choices fall back to portable on a CPU without AVX-512F. The environment variable
// CVD_DEPTHWISE_KERNEL=portable|blocked|direct sets the choice at start-up.
enum class DepthwiseKernel { automatic, portable, blocked_avx512, direct_avx512 };
void set_depthwise_kernel(DepthwiseKernel kernel);

}  // namespace cvd::cpu
