// Hand-written dense 2-D convolution for few output channels (1-8) on NCHW tensors: forward and
// backward weights, stride 1, no dilation, one group, AVX-512.
//
// Why it exists: the default network (Mannequin at width 1/8) has inception branches with 7x7 and
// 11x11 filters into 2 or 4 channels at full resolution. oneDNN 2.6 runs those at 27-31 GFLOP/s
// (forward on jit:avx512_core, backward weights on jit:avx2: its blocked kernels vectorise over
// output channels, of which there are 2): the 8 -> 2 11x11 layer alone took 5.7 s of the
// demo's 41 s of training. Here the vectors run along the image row instead: the input is copied
// once into zero-padded rows, every filter tap is one unaligned row load shared by all output
// channels, and the output pixels (forward) or the filter taps (backward weights) are accumulated
// in registers. Up to 8 outputs since 2026-12-07: the network's 4 -> 8 and 8 -> 8 branches, and
// the 2 -> 8 forward problem that 8 -> 2's backward data is (2x oneDNN on those shapes).
#pragma once
#include <cstdint>

namespace cvd::cpu {

// x [n, c, h, w] -> y [n, o, oh, ow] with w [o, c, kh, kw]; stride 1, dilation 1, one group.
// Padding: pad_top / pad_left zero rows / columns before the input; oh, ow give the rest.
struct NarrowConvGeometry {
  int64_t n = 0, c = 0, h = 0, w = 0, o = 0, oh = 0, ow = 0, kh = 0, kw = 0;
  int64_t pad_top = 0, pad_left = 0;
};

constexpr int kNarrowConvMaxOutputChannels = 8;
// The padded copy of the input holds every input channel of the batch: Mannequin's full-width
// 64 -> 1 3x3 heads (224x384, batch 8) made it 186 MB and the training step 3% slower than
// oneDNN, so wider inputs stay with oneDNN (the default network's narrow layers read 2-16).
constexpr int64_t kNarrowConvMaxInputChannels = 16;

// AVX-512F present (the kernel is compiled for it and called only then).
bool narrow_conv2d_supported();

// y = conv(x, w) + b (b may be null).
void narrow_conv2d_forward(const NarrowConvGeometry& g, const float* x, const float* w,
                           const float* b, float* y);

// gw [o, c, kh, kw] from gy [n, o, oh, ow] and x (the bias gradient is the caller's).
void narrow_conv2d_backward_weight(const NarrowConvGeometry& g, const float* gy, const float* x,
                                   float* gw);

}  // namespace cvd::cpu
