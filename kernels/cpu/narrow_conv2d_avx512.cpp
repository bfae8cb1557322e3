// AVX-512 dense convolution for 1-8 output channels (see narrow_conv2d.h). The input is copied
// once per call into zero-padded rows (every tap then reads a whole row segment without bounds
// checks); vectors run along the output row.
//  - forward: a tile of 2-4 x 16 output pixels of one row, for every output channel, accumulates in
//    registers over input channels and filter taps: one unaligned load per tap and 16 pixels,
//    shared by the output channels (weights broadcast);
//  - backward weights: for one input channel, one filter row and up to 12 filter columns, every
//    (output channel, tap) pair accumulates a vector of products over the whole batch, reduced
//    horizontally at the end; each task owns its weights, so no reduction between threads.
#include "kernels/cpu/narrow_conv2d.h"

#include <immintrin.h>

#include <algorithm>
#include <cstring>
#include <type_traits>
#include <utility>

#include "engine/error.h"
#include "kernels/cpu/aligned_float_buffer.h"
#include "kernels/cpu/cpu_parallel.h"

#if defined(__GNUC__) && defined(__x86_64__)

#define CVD_AVX512 __attribute__((target("avx512f")))

namespace cvd::cpu {

namespace {

constexpr int64_t L = 16;  // floats per vector
// Vectors of output pixels per forward tile: O x V accumulators stay within 16 registers, so the
// O broadcast weights and the row loads fit beside them (4 up to 4 outputs, then 3, then 2).
constexpr int tile_vectors(int O) { return O <= 4 ? 4 : O == 5 ? 3 : 2; }

// Zero-padded copy of x: rows of wp floats, hp rows per plane; row py, column px holds
// x[py - pad_top][px - pad_left] (zero outside). wp covers every vector a tile or tap reads.
struct PaddedInput {
  int64_t hp = 0, wp = 0;
  const float* data = nullptr;
  const float* plane(int64_t n, int64_t c, int64_t C) const { return data + (n * C + c) * hp * wp; }
};

PaddedInput pad_input(const NarrowConvGeometry& g, const float* x, AlignedFloatBuffer& buf) {
  PaddedInput p;
  p.hp = g.oh + g.kh - 1;
  p.wp = (g.ow + L - 1) / L * L + g.kw - 1 + L;  // + one vector: the widest chunk's spill
  const int64_t planes = g.n * g.c, plane = p.hp * p.wp;
  float* d = buf.get(planes * plane);
  const int64_t copy = std::min(g.w, p.wp - g.pad_left);
  parallel_ranges(planes, plane, [&](int64_t begin, int64_t end) {
    for (int64_t q = begin; q < end; ++q) {
      const float* src = x + q * g.h * g.w;
      float* dst = d + q * plane;
      for (int64_t py = 0; py < p.hp; ++py) {
        float* row = dst + py * p.wp;
        const int64_t iy = py - g.pad_top;
        if (iy < 0 || iy >= g.h || copy <= 0) {
          std::memset(row, 0, p.wp * sizeof(float));
          continue;
        }
        std::memset(row, 0, g.pad_left * sizeof(float));
        std::memcpy(row + g.pad_left, src + iy * g.w, copy * sizeof(float));
        std::memset(row + g.pad_left + copy, 0, (p.wp - g.pad_left - copy) * sizeof(float));
      }
    }
  });
  p.data = d;
  return p;
}

__mmask16 lanes(int64_t n) {
  return n >= L ? static_cast<__mmask16>(0xffff) : static_cast<__mmask16>((1u << n) - 1);
}

// ---- Forward ------------------------------------------------------------------------------------

// Output pixels [x0, x0 + 16 NV) of row oy (the last vector masked to `last`) of every output
// channel of image n. wpk: weights as [c][ky][kx][o].
template <int O, int NV>
CVD_AVX512 void forward_tile(const NarrowConvGeometry& g, const PaddedInput& p, int64_t n,
                             const float* wpk, const float* b, int64_t oy, int64_t x0,
                             __mmask16 last, float* y) {
  __m512 acc[O][NV];
#pragma GCC unroll 16
  for (int o = 0; o < O; ++o) {
    const __m512 bv = _mm512_set1_ps(b ? b[o] : 0.0f);
#pragma GCC unroll 16
    for (int v = 0; v < NV; ++v) acc[o][v] = bv;
  }
  for (int64_t c = 0; c < g.c; ++c) {
    const float* plane = p.plane(n, c, g.c);
    for (int64_t ky = 0; ky < g.kh; ++ky) {
      const float* row = plane + (oy + ky) * p.wp + x0;
      const float* wr = wpk + (c * g.kh + ky) * g.kw * O;
      for (int64_t kx = 0; kx < g.kw; ++kx) {
        __m512 wv[O];
#pragma GCC unroll 16
        for (int o = 0; o < O; ++o) wv[o] = _mm512_set1_ps(wr[kx * O + o]);
#pragma GCC unroll 16
        for (int v = 0; v < NV; ++v) {
          const __m512 in = _mm512_loadu_ps(row + kx + v * L);
#pragma GCC unroll 16
          for (int o = 0; o < O; ++o) acc[o][v] = _mm512_fmadd_ps(wv[o], in, acc[o][v]);
        }
      }
    }
  }
  const int64_t oplane = g.oh * g.ow;
#pragma GCC unroll 16
  for (int o = 0; o < O; ++o) {
    float* out = y + (n * g.o + o) * oplane + oy * g.ow + x0;
#pragma GCC unroll 16
    for (int v = 0; v + 1 < NV; ++v) _mm512_storeu_ps(out + v * L, acc[o][v]);
    _mm512_mask_storeu_ps(out + (NV - 1) * L, last, acc[o][NV - 1]);
  }
}

template <int O, int NV = tile_vectors(O)>
CVD_AVX512 void forward_tile_of_width(int vectors, const NarrowConvGeometry& g,
                                      const PaddedInput& p, int64_t n, const float* wpk,
                                      const float* b, int64_t oy, int64_t x0, __mmask16 last,
                                      float* y) {
  if constexpr (NV >= 1) {
    if (vectors == NV) return forward_tile<O, NV>(g, p, n, wpk, b, oy, x0, last, y);
    forward_tile_of_width<O, NV - 1>(vectors, g, p, n, wpk, b, oy, x0, last, y);
  }
}

template <int O>
CVD_AVX512 void forward_row(const NarrowConvGeometry& g, const PaddedInput& p, int64_t n,
                            const float* wpk, const float* b, int64_t oy, float* y) {
  constexpr int V = tile_vectors(O);
  for (int64_t x0 = 0; x0 < g.ow; x0 += V * L) {
    const int64_t vectors = std::min<int64_t>(V, (g.ow - x0 + L - 1) / L);
    const __mmask16 last = lanes(g.ow - x0 - (vectors - 1) * L);
    forward_tile_of_width<O>(static_cast<int>(vectors), g, p, n, wpk, b, oy, x0, last, y);
  }
}

template <int O>
void forward_rows(const NarrowConvGeometry& g, const PaddedInput& p, const float* wpk,
                  const float* b, float* y) {
  const int64_t row_cost = g.ow * g.c * g.kh * g.kw * O;
  parallel_ranges(g.n * g.oh, row_cost, [&](int64_t begin, int64_t end) {
    for (int64_t r = begin; r < end; ++r) forward_row<O>(g, p, r / g.oh, wpk, b, r % g.oh, y);
  });
}

// ---- Backward weights ---------------------------------------------------------------------------

// Taps kx0 .. kx0 + K - 1 of filter row ky, input channel c, every output channel: the products
// of the output gradient with the shifted padded input, summed over the batch.
template <int O, int K>
CVD_AVX512 void weight_chunk(const NarrowConvGeometry& g, const PaddedInput& p, const float* gy,
                             int64_t c, int64_t ky, int64_t kx0, float* gw) {
  __m512 acc[O][K];
#pragma GCC unroll 16
  for (int o = 0; o < O; ++o)
#pragma GCC unroll 16
    for (int k = 0; k < K; ++k) acc[o][k] = _mm512_setzero_ps();
  const int64_t oplane = g.oh * g.ow;
  for (int64_t n = 0; n < g.n; ++n) {
    const float* plane = p.plane(n, c, g.c);
    const float* gyn = gy + n * g.o * oplane;
    for (int64_t oy = 0; oy < g.oh; ++oy) {
      const float* row = plane + (oy + ky) * p.wp + kx0;
      const float* grow = gyn + oy * g.ow;
      for (int64_t x0 = 0; x0 < g.ow; x0 += L) {
        const __mmask16 m = lanes(g.ow - x0);
        __m512 gv[O];
#pragma GCC unroll 16
        for (int o = 0; o < O; ++o) gv[o] = _mm512_maskz_loadu_ps(m, grow + o * oplane + x0);
#pragma GCC unroll 16
        for (int k = 0; k < K; ++k) {
          const __m512 in = _mm512_loadu_ps(row + x0 + k);
#pragma GCC unroll 16
          for (int o = 0; o < O; ++o) acc[o][k] = _mm512_fmadd_ps(gv[o], in, acc[o][k]);
        }
      }
    }
  }
#pragma GCC unroll 16
  for (int o = 0; o < O; ++o)
#pragma GCC unroll 16
    for (int k = 0; k < K; ++k)
      gw[((o * g.c + c) * g.kh + ky) * g.kw + kx0 + k] = _mm512_reduce_add_ps(acc[o][k]);
}

// Filter columns per chunk: O x K accumulators stay within 24 of the 32 vector registers.
constexpr int max_chunk(int O) { return O == 1 ? 12 : 24 / O; }

template <int O, int K = max_chunk(O)>
void weight_chunk_of_width(int width, const NarrowConvGeometry& g, const PaddedInput& p,
                           const float* gy, int64_t c, int64_t ky, int64_t kx0, float* gw) {
  if constexpr (K >= 1) {
    if (width == K) return weight_chunk<O, K>(g, p, gy, c, ky, kx0, gw);
    weight_chunk_of_width<O, K - 1>(width, g, p, gy, c, ky, kx0, gw);
  }
}

template <int O>
void backward_weight_chunks(const NarrowConvGeometry& g, const PaddedInput& p, const float* gy,
                            float* gw) {
  const int64_t chunks = (g.kw + max_chunk(O) - 1) / max_chunk(O);
  const int64_t width = (g.kw + chunks - 1) / chunks;  // the last chunk may be narrower
  const int64_t tasks = g.c * g.kh * chunks;
  const int64_t task_cost = g.n * g.oh * g.ow * width * O;
  parallel_ranges(tasks, task_cost, [&](int64_t begin, int64_t end) {
    for (int64_t t = begin; t < end; ++t) {
      const int64_t chunk = t % chunks, ky = (t / chunks) % g.kh, c = t / (chunks * g.kh);
      const int64_t kx0 = chunk * width;
      const int w = static_cast<int>(std::min(width, g.kw - kx0));
      weight_chunk_of_width<O>(w, g, p, gy, c, ky, kx0, gw);
    }
  });
}

// Per-call work space of the calling thread: the padded input.
AlignedFloatBuffer& padded_buffer() {
  thread_local AlignedFloatBuffer buf;
  return buf;
}

// The padding the geometry implies on the bottom and right must not be negative.
void check_geometry(const NarrowConvGeometry& g) {
  if (g.o < 1 || g.o > kNarrowConvMaxOutputChannels || g.pad_top < 0 || g.pad_left < 0 ||
      g.oh < 1 || g.ow < 1 || g.oh + g.kh - 1 < g.h + g.pad_top ||
      g.ow + g.kw - 1 < g.w + g.pad_left)
    fail(ErrorCategory::internal,
         "narrow_conv2d: unsupported geometry ({} output channels, {}x{} -> {}x{}, pads {} {})",
         g.o, g.h, g.w, g.oh, g.ow, g.pad_top, g.pad_left);
}

// Calls f with std::integral_constant<int, o> for o in 1 .. kNarrowConvMaxOutputChannels.
template <int O = 1, class F>
void with_output_count(int64_t o, F&& f) {
  if constexpr (O <= kNarrowConvMaxOutputChannels) {
    if (o == O) return f(std::integral_constant<int, O>{});
    with_output_count<O + 1>(o, std::forward<F>(f));
  }
}

}  // namespace

bool narrow_conv2d_supported() {
  static const bool ok = __builtin_cpu_supports("avx512f");
  return ok;
}

void narrow_conv2d_forward(const NarrowConvGeometry& g, const float* x, const float* w,
                           const float* b, float* y) {
  check_geometry(g);
  const PaddedInput p = pad_input(g, x, padded_buffer());
  // Weights as [c][ky][kx][o]: the output channels of one tap side by side.
  const int64_t taps = g.c * g.kh * g.kw;
  thread_local AlignedFloatBuffer wbuf;
  float* wpk = wbuf.get(taps * g.o);
  for (int64_t o = 0; o < g.o; ++o)
    for (int64_t t = 0; t < taps; ++t) wpk[t * g.o + o] = w[o * taps + t];
  with_output_count(g.o, [&](auto o) { forward_rows<decltype(o)::value>(g, p, wpk, b, y); });
}

void narrow_conv2d_backward_weight(const NarrowConvGeometry& g, const float* gy, const float* x,
                                   float* gw) {
  check_geometry(g);
  const PaddedInput p = pad_input(g, x, padded_buffer());
  with_output_count(g.o, [&](auto o) { backward_weight_chunks<decltype(o)::value>(g, p, gy, gw); });
}

}  // namespace cvd::cpu

#else

namespace cvd::cpu {
bool narrow_conv2d_supported() { return false; }
void narrow_conv2d_forward(const NarrowConvGeometry&, const float*, const float*, const float*,
                           float*) {}
void narrow_conv2d_backward_weight(const NarrowConvGeometry&, const float*, const float*, float*) {}
}  // namespace cvd::cpu

#endif
