// Internal: the two implementations behind cpu/depthwise_conv2d.h, each over a channel range
// [c0, c1) of the NCHW tensors (the public functions split the channels between them).
//   portable: wide-plane loops any compiler vectorizes (cloned for AVX-512 / AVX2 / baseline);
//   avx512:   16 channels per vector, planes transposed in cache into a channel-interleaved
//             zero-padded block (the layout oneDNN's depthwise kernels use), register-blocked
//             multiply-adds, transposed back; needs c1 - c0 to be a multiple of 16.
//   direct:   AVX-512 on the NCHW planes themselves, every pass a stride-1 correlation over
//             zero-padded stride phases (forward and backward data only).
#pragma once
#include <cstdint>

#include "kernels/cpu/aligned_float_buffer.h"
#include "kernels/cpu/depthwise_conv2d.h"

namespace cvd::cpu::depthwise {

void forward_portable(const DepthwiseGeometry& g, int64_t c0, int64_t c1, const float* x,
                      const float* w, const float* b, float* y);
void backward_data_portable(const DepthwiseGeometry& g, int64_t c0, int64_t c1, const float* gy,
                            const float* w, float* gx);
void backward_weight_portable(const DepthwiseGeometry& g, int64_t c0, int64_t c1, const float* gy,
                              const float* x, float* gw, float* gb);

bool avx512_supported();
void forward_avx512(const DepthwiseGeometry& g, int64_t c0, int64_t c1, const float* x,
                    const float* w, const float* b, float* y);
void backward_data_avx512(const DepthwiseGeometry& g, int64_t c0, int64_t c1, const float* gy,
                          const float* w, float* gx);
void backward_weight_avx512(const DepthwiseGeometry& g, int64_t c0, int64_t c1, const float* gy,
                            const float* x, float* gw, float* gb);

void forward_direct_avx512(const DepthwiseGeometry& g, int64_t c0, int64_t c1, const float* x,
                           const float* w, const float* b, float* y);
void backward_data_direct_avx512(const DepthwiseGeometry& g, int64_t c0, int64_t c1,
                                 const float* gy, const float* w, float* gx);

}  // namespace cvd::cpu::depthwise
