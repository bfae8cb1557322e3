// Depthwise 2-D convolution on NCHW planes (see depthwise_conv2d.h): the public entry points,
// and the portable implementation (depthwise_conv2d_kernels.h).
//
// Layout trick ("wide planes"): one input plane is copied, zero padded, into sh * sw phase planes
// of hq x wq floats, phase (ry, rx) holding padded pixel (j * sh + ry, k * sw + rx) at j * wq + k.
// The output is computed as an oh x wq "wide" plane whose columns ow..wq-1 are discarded. Filter
// tap (ky, kx) then reads one phase plane at the constant offset
// (ky * dh / sh) * wq + (kx * dw / sw) from the output index, so every tap is a single
// unit-stride multiply-add over the whole wide plane (long loops, no bounds checks), for any
// stride, dilation and padding.
#include "kernels/cpu/depthwise_conv2d.h"

#include "kernels/cpu/depthwise_conv2d_kernels.h"

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "kernels/cpu/cpu_parallel.h"

// Clones of the per-plane loops for x86-64-v4 (AVX-512) and v3 (AVX2 + FMA) machines, picked at
// load time by CPU features (the library is built for baseline x86-64).
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define CVD_DEPTHWISE_CLONES \
  __attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#define CVD_INLINE __attribute__((always_inline)) inline
#else
#define CVD_DEPTHWISE_CLONES
#define CVD_INLINE inline
#endif

namespace cvd::cpu {

namespace {

struct WidePlan {
  int64_t sh = 1, sw = 1, hq = 0, wq = 0;
  int64_t block = 0;         // wide-plane elements per pass (whole rows, a few KiB: stays in L1)
  std::vector<int64_t> tap;  // offset of each filter tap (ky-major) in the phase planes
  int64_t phase_size() const { return hq * wq; }
  int64_t phases_size() const { return sh * sw * hq * wq; }
};

WidePlan wide_plan(const DepthwiseGeometry& g) {
  WidePlan p;
  p.sh = g.stride_h, p.sw = g.stride_w;
  p.wq = g.ow + (g.kw - 1) * g.dil_w / g.stride_w;
  p.hq = g.oh + (g.kh - 1) * g.dil_h / g.stride_h + 1;
  p.block = std::max<int64_t>(1, 2048 / p.wq) * p.wq;
  for (int64_t ky = 0; ky < g.kh; ++ky) {
    for (int64_t kx = 0; kx < g.kw; ++kx) {
      const int64_t py = ky * g.dil_h, px = kx * g.dil_w;
      const int64_t phase = (py % p.sh) * p.sw + px % p.sw;
      p.tap.push_back(phase * p.phase_size() + (py / p.sh) * p.wq + px / p.sw);
    }
  }
  return p;
}

// Copies plane x [h, w] into the zero-padded phase planes.
CVD_INLINE void split_plane(const DepthwiseGeometry& g, const WidePlan& p, const float* x,
                            float* phases) {
  for (int64_t ry = 0; ry < p.sh; ++ry) {
    for (int64_t rx = 0; rx < p.sw; ++rx) {
      float* plane = phases + (ry * p.sw + rx) * p.phase_size();
      for (int64_t j = 0; j < p.hq; ++j) {
        float* dst = plane + j * p.wq;
        const int64_t iy = j * p.sh + ry - g.pad_top;
        if (iy < 0 || iy >= g.h) {
          std::fill(dst, dst + p.wq, 0.0f);
          continue;
        }
        const float* row = x + iy * g.w;
        if (p.sw == 1) {
          const int64_t begin = std::min(g.pad_left, p.wq);
          const int64_t end = std::min(g.pad_left + g.w, p.wq);
          std::fill(dst, dst + begin, 0.0f);
          if (end > begin) std::memcpy(dst + begin, row, (end - begin) * sizeof(float));
          std::fill(dst + std::max(begin, end), dst + p.wq, 0.0f);
        } else {
          for (int64_t k = 0; k < p.wq; ++k) {
            const int64_t ix = k * p.sw + rx - g.pad_left;
            dst[k] = (ix >= 0 && ix < g.w) ? row[ix] : 0.0f;
          }
        }
      }
    }
  }
}

// gy plane [oh, ow] into an oh x wq wide plane whose extra columns are zero.
CVD_INLINE void widen_plane(const DepthwiseGeometry& g, const WidePlan& p, const float* gy,
                            float* wide) {
  for (int64_t oy = 0; oy < g.oh; ++oy) {
    std::memcpy(wide + oy * p.wq, gy + oy * g.ow, g.ow * sizeof(float));
    std::fill(wide + oy * p.wq + g.ow, wide + (oy + 1) * p.wq, 0.0f);
  }
}

CVD_INLINE void multiply_add(float* __restrict acc, const float* __restrict s, float f, int64_t n) {
  for (int64_t i = 0; i < n; ++i) acc[i] += f * s[i];
}

CVD_INLINE void multiply_add4(float* __restrict acc, const float* __restrict s0,
                              const float* __restrict s1, const float* __restrict s2,
                              const float* __restrict s3, const float* f, int64_t n) {
  const float f0 = f[0], f1 = f[1], f2 = f[2], f3 = f[3];
  for (int64_t i = 0; i < n; ++i) acc[i] += f0 * s0[i] + f1 * s1[i] + f2 * s2[i] + f3 * s3[i];
}

CVD_INLINE float dot(const float* __restrict a, const float* __restrict b, int64_t n) {
  float s = 0.0f;
#pragma omp simd reduction(+ : s)
  for (int64_t i = 0; i < n; ++i) s += a[i] * b[i];
  return s;
}

// One (image, channel) plane of the forward pass. work: phases + oh * wq floats.
CVD_DEPTHWISE_CLONES
void forward_plane(const DepthwiseGeometry& g, const WidePlan& p, const float* x, const float* filt,
                   float bias, float* y, float* work) {
  float* phases = work;
  float* acc = work + p.phases_size();
  const int64_t n = g.oh * p.wq, taps = g.kh * g.kw;
  split_plane(g, p, x, phases);
  std::fill(acc, acc + n, bias);
  for (int64_t b0 = 0; b0 < n; b0 += p.block) {
    const int64_t len = std::min(p.block, n - b0);
    float* a = acc + b0;
    const float* src = phases + b0;
    int64_t t = 0;
    for (; t + 4 <= taps; t += 4) {
      multiply_add4(a, src + p.tap[t], src + p.tap[t + 1], src + p.tap[t + 2], src + p.tap[t + 3],
                    filt + t, len);
    }
    for (; t < taps; ++t) multiply_add(a, src + p.tap[t], filt[t], len);
  }
  for (int64_t oy = 0; oy < g.oh; ++oy) {
    std::memcpy(y + oy * g.ow, acc + oy * p.wq, g.ow * sizeof(float));
  }
}

// One plane of the backward-data pass: every tap scatters the wide output gradient into the
// phase planes of the input gradient, which are then gathered back. work: phases + oh * wq.
CVD_DEPTHWISE_CLONES
void backward_data_plane(const DepthwiseGeometry& g, const WidePlan& p, const float* gy,
                         const float* filt, float* gx, float* work) {
  float* phases = work;
  float* wide = work + p.phases_size();
  const int64_t n = g.oh * p.wq, taps = g.kh * g.kw;
  widen_plane(g, p, gy, wide);
  std::fill(phases, phases + p.phases_size(), 0.0f);
  for (int64_t b0 = 0; b0 < n; b0 += p.block) {
    const int64_t len = std::min(p.block, n - b0);
    for (int64_t t = 0; t < taps; ++t) {
      multiply_add(phases + b0 + p.tap[t], wide + b0, filt[t], len);
    }
  }
  for (int64_t iy = 0; iy < g.h; ++iy) {
    const int64_t py = iy + g.pad_top, j = py / p.sh;
    float* out = gx + iy * g.w;
    if (j >= p.hq) {
      std::fill(out, out + g.w, 0.0f);
      continue;
    }
    const float* rows = phases + (py % p.sh) * p.sw * p.phase_size() + j * p.wq;
    for (int64_t ix = 0; ix < g.w; ++ix) {
      const int64_t px = ix + g.pad_left, k = px / p.sw;
      out[ix] = k < p.wq ? rows[(px % p.sw) * p.phase_size() + k] : 0.0f;
    }
  }
}

// One channel of the backward-weights pass over all images, summed in double per plane.
// work: phases + oh * wq floats.
CVD_DEPTHWISE_CLONES
void backward_weight_channel(const DepthwiseGeometry& g, const WidePlan& p, int64_t c,
                             const float* gy, const float* x, double* acc, double* bias_acc,
                             float* work) {
  float* phases = work;
  float* wide = work + p.phases_size();
  const int64_t n = g.oh * p.wq, taps = g.kh * g.kw;
  for (int64_t img = 0; img < g.n; ++img) {
    split_plane(g, p, x + (img * g.c + c) * g.h * g.w, phases);
    widen_plane(g, p, gy + (img * g.c + c) * g.oh * g.ow, wide);
    for (int64_t b0 = 0; b0 < n; b0 += p.block) {
      const int64_t len = std::min(p.block, n - b0);
      for (int64_t t = 0; t < taps; ++t) acc[t] += dot(wide + b0, phases + b0 + p.tap[t], len);
    }
    if (bias_acc != nullptr) {
      float s = 0.0f;
#pragma omp simd reduction(+ : s)
      for (int64_t i = 0; i < n; ++i) s += wide[i];
      *bias_acc += s;
    }
  }
}

}  // namespace

namespace depthwise {

void forward_portable(const DepthwiseGeometry& g, int64_t c0, int64_t c1, const float* x,
                      const float* w, const float* b, float* y) {
  const WidePlan p = wide_plan(g);
  const int64_t taps = g.kh * g.kw, nc = c1 - c0;
  parallel_ranges(g.n * nc, g.oh * p.wq * taps, [&](int64_t begin, int64_t end) {
    std::vector<float> work(static_cast<size_t>(p.phases_size() + g.oh * p.wq));
    for (int64_t i = begin; i < end; ++i) {
      const int64_t c = c0 + i % nc, plane = (i / nc) * g.c + c;
      forward_plane(g, p, x + plane * g.h * g.w, w + c * taps, b ? b[c] : 0.0f,
                    y + plane * g.oh * g.ow, work.data());
    }
  });
}

void backward_data_portable(const DepthwiseGeometry& g, int64_t c0, int64_t c1, const float* gy,
                            const float* w, float* gx) {
  const WidePlan p = wide_plan(g);
  const int64_t taps = g.kh * g.kw, nc = c1 - c0;
  parallel_ranges(g.n * nc, g.oh * p.wq * taps, [&](int64_t begin, int64_t end) {
    std::vector<float> work(static_cast<size_t>(p.phases_size() + g.oh * p.wq));
    for (int64_t i = begin; i < end; ++i) {
      const int64_t c = c0 + i % nc, plane = (i / nc) * g.c + c;
      backward_data_plane(g, p, gy + plane * g.oh * g.ow, w + c * taps, gx + plane * g.h * g.w,
                          work.data());
    }
  });
}

void backward_weight_portable(const DepthwiseGeometry& g, int64_t c0, int64_t c1, const float* gy,
                              const float* x, float* gw, float* gb) {
  const WidePlan p = wide_plan(g);
  const int64_t taps = g.kh * g.kw;
  parallel_ranges(c1 - c0, g.n * g.oh * p.wq * taps, [&](int64_t begin, int64_t end) {
    std::vector<float> work(static_cast<size_t>(p.phases_size() + g.oh * p.wq));
    std::vector<double> acc(static_cast<size_t>(taps));
    for (int64_t c = c0 + begin; c < c0 + end; ++c) {
      std::fill(acc.begin(), acc.end(), 0.0);
      double bias_acc = 0.0;
      backward_weight_channel(g, p, c, gy, x, acc.data(), gb ? &bias_acc : nullptr, work.data());
      for (int64_t k = 0; k < taps; ++k) gw[c * taps + k] = static_cast<float>(acc[k]);
      if (gb) gb[c] = static_cast<float>(bias_acc);
    }
  });
}

}  // namespace depthwise

namespace {

// CVD_DEPTHWISE_KERNEL=portable|blocked|direct sets the start value (to measure one against the
// others in a whole network); unset or anything else: automatic (another value is reported once).
DepthwiseKernel kernel_from_environment() {
  const char* v = std::getenv("CVD_DEPTHWISE_KERNEL");
  if (v == nullptr || *v == '\0' || std::strcmp(v, "automatic") == 0) {
    return DepthwiseKernel::automatic;
  }
  if (std::strcmp(v, "portable") == 0) return DepthwiseKernel::portable;
  if (std::strcmp(v, "blocked") == 0) return DepthwiseKernel::blocked_avx512;
  if (std::strcmp(v, "direct") == 0) return DepthwiseKernel::direct_avx512;
  std::fprintf(stderr,
               "cvd: CVD_DEPTHWISE_KERNEL=%s is not one of automatic, portable, blocked, direct; "
               "using automatic\n",
               v);
  return DepthwiseKernel::automatic;
}

std::atomic<DepthwiseKernel> g_kernel{kernel_from_environment()};

// The implementation for forward and backward data (`automatic` resolved): on AVX-512, direct
// for unit stride, blocked for larger strides. Measured (bench/compare_conv.sh, MiDaS small's
// 5x5 depthwise layers, AMD EPYC Zen 5): at unit stride direct is 1.1-1.4x blocked; at stride 2
// the direct kernel's phase split and short rows make it 0.6-1.0x blocked.
DepthwiseKernel chosen_kernel(const DepthwiseGeometry& g) {
  static const bool avx512 = depthwise::avx512_supported();
  if (!avx512) return DepthwiseKernel::portable;
  const DepthwiseKernel k = g_kernel.load(std::memory_order_relaxed);
  if (k != DepthwiseKernel::automatic) return k;
  return g.stride_h == 1 && g.stride_w == 1 ? DepthwiseKernel::direct_avx512
                                            : DepthwiseKernel::blocked_avx512;
}

// Channels [0, returned) go to the blocked AVX-512 implementation, the rest to the portable one.
int64_t blocked_channels(const DepthwiseGeometry& g) { return g.c / 16 * 16; }

}  // namespace

void set_depthwise_kernel(DepthwiseKernel kernel) { g_kernel = kernel; }

void depthwise_conv2d_forward(const DepthwiseGeometry& g, const float* x, const float* w,
                              const float* b, float* y) {
  switch (chosen_kernel(g)) {
    case DepthwiseKernel::automatic:
    case DepthwiseKernel::direct_avx512:
      return depthwise::forward_direct_avx512(g, 0, g.c, x, w, b, y);
    case DepthwiseKernel::blocked_avx512: {
      const int64_t split = blocked_channels(g);
      if (split > 0) depthwise::forward_avx512(g, 0, split, x, w, b, y);
      if (split < g.c) depthwise::forward_portable(g, split, g.c, x, w, b, y);
      return;
    }
    case DepthwiseKernel::portable:
      return depthwise::forward_portable(g, 0, g.c, x, w, b, y);
  }
}

void depthwise_conv2d_backward_data(const DepthwiseGeometry& g, const float* gy, const float* w,
                                    float* gx) {
  switch (chosen_kernel(g)) {
    case DepthwiseKernel::automatic:
    case DepthwiseKernel::direct_avx512:
      return depthwise::backward_data_direct_avx512(g, 0, g.c, gy, w, gx);
    case DepthwiseKernel::blocked_avx512: {
      const int64_t split = blocked_channels(g);
      if (split > 0) depthwise::backward_data_avx512(g, 0, split, gy, w, gx);
      if (split < g.c) depthwise::backward_data_portable(g, split, g.c, gy, w, gx);
      return;
    }
    case DepthwiseKernel::portable:
      return depthwise::backward_data_portable(g, 0, g.c, gy, w, gx);
  }
}

void depthwise_conv2d_backward_weight(const DepthwiseGeometry& g, const float* gy, const float* x,
                                      float* gw, float* gb) {
  const int64_t split = chosen_kernel(g) == DepthwiseKernel::portable ? 0 : blocked_channels(g);
  if (split > 0) depthwise::backward_weight_avx512(g, 0, split, gy, x, gw, gb);
  if (split < g.c) depthwise::backward_weight_portable(g, split, g.c, gy, x, gw, gb);
}

}  // namespace cvd::cpu
