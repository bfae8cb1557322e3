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
#include <cstdlib>
#include <memory>
#include <new>

#include "kernels/cpu/depthwise_conv2d.h"

namespace cvd::cpu::depthwise {

// A 64-byte aligned float buffer that grows on demand (contents not kept across growth, not
// initialised): the AVX-512 implementations' per-thread work space.
class AlignedFloatBuffer {
 public:
  float* get(int64_t floats) {
    if (floats > size_) {
      const size_t bytes = (static_cast<size_t>(floats) * sizeof(float) + 63) / 64 * 64;
      data_.reset(static_cast<float*>(std::aligned_alloc(64, bytes)));
      if (!data_) throw std::bad_alloc();
      size_ = floats;
    }
    return data_.get();
  }

 private:
  struct Free {
    void operator()(float* p) const { std::free(p); }
  };
  std::unique_ptr<float, Free> data_;
  int64_t size_ = 0;
};

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
