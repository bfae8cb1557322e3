// AVX-512 depthwise convolution (see depthwise_conv2d_kernels.h). Work unit: one image and 16
// channels. Their 16 NCHW planes are transposed (16 x 16 register transposes) into a zero-padded
// buffer of channel-interleaved pixels that stays in L2; every filter tap is then one aligned
// vector load and one fused multiply-add per output pixel, with 8 output pixels accumulated in
// registers (forward and unit-stride backward data: 16, transposed in registers and stored
// straight into the NCHW planes with masked stores); other results are transposed back into the
// NCHW planes. Compiled with a target attribute and only called when the CPU reports AVX-512F.
#include <immintrin.h>

#include <algorithm>
#include <cstring>
#include <vector>

#include "kernels/cpu/cpu_parallel.h"
#include "kernels/cpu/depthwise_conv2d_kernels.h"

#if defined(__GNUC__) && defined(__x86_64__)

#define CVD_AVX512 __attribute__((target("avx512f")))

// GCC 12 reports the intrinsics' internal undefined pass-through operands (_mm512_undefined_*)
// as (maybe-)uninitialized once the transposes of partly constant tiles are inlined (a known
// false positive at -O3); every vector here is written before it is read.
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"

namespace cvd::cpu::depthwise {

namespace {

constexpr int64_t L = 16;  // channels per vector
constexpr int U = 8;       // output pixels accumulated in registers

// Rows x columns of the zero-padded input every output pixel and tap reads from.
struct PaddedInput {
  int64_t hp, wp;
};

PaddedInput padded_input(const DepthwiseGeometry& g) {
  return {std::max(g.pad_top + g.h, (g.oh - 1) * g.stride_h + (g.kh - 1) * g.dil_h + 1),
          std::max(g.pad_left + g.w, (g.ow - 1) * g.stride_w + (g.kw - 1) * g.dil_w + 1)};
}

// In-register transpose of a 16 x 16 float tile (an involution).
CVD_AVX512 inline void transpose16(__m512 r[16]) {
  __m512 t[16];
  for (int i = 0; i < 8; ++i) {
    t[2 * i] = _mm512_unpacklo_ps(r[2 * i], r[2 * i + 1]);
    t[2 * i + 1] = _mm512_unpackhi_ps(r[2 * i], r[2 * i + 1]);
  }
  for (int i = 0; i < 4; ++i) {
    const __m512d a = _mm512_castps_pd(t[4 * i]), b = _mm512_castps_pd(t[4 * i + 1]);
    const __m512d c = _mm512_castps_pd(t[4 * i + 2]), d = _mm512_castps_pd(t[4 * i + 3]);
    r[4 * i + 0] = _mm512_castpd_ps(_mm512_unpacklo_pd(a, c));
    r[4 * i + 1] = _mm512_castpd_ps(_mm512_unpackhi_pd(a, c));
    r[4 * i + 2] = _mm512_castpd_ps(_mm512_unpacklo_pd(b, d));
    r[4 * i + 3] = _mm512_castpd_ps(_mm512_unpackhi_pd(b, d));
  }
  for (int i = 0; i < 2; ++i) {
    for (int j = 0; j < 4; ++j) {
      t[8 * i + j] = _mm512_shuffle_f32x4(r[8 * i + j], r[8 * i + 4 + j], 0x88);
      t[8 * i + 4 + j] = _mm512_shuffle_f32x4(r[8 * i + j], r[8 * i + 4 + j], 0xdd);
    }
  }
  for (int j = 0; j < 8; ++j) {
    r[j] = _mm512_shuffle_f32x4(t[j], t[8 + j], 0x88);
    r[8 + j] = _mm512_shuffle_f32x4(t[j], t[8 + j], 0xdd);
  }
}

// Address (in floats) of pixel i of an h x w image stored as channel-interleaved rows of
// row_w pixels from row y0, column x0; walks the pixels in order.
struct PixelCursor {
  int64_t w, row_w, y, x;
  int64_t offset() const { return (y * row_w + x) * L; }
  void next(int64_t x0) {
    if (++x == x0 + w) x = x0, ++y;
  }
};

// 16 planes (src + c * plane_stride, h x w each, contiguous) into channel-interleaved rows of
// dst_w pixels, placed at row y0, column x0. Tiles run over the flattened plane, so narrow
// images need no scalar tails except the last few pixels.
CVD_AVX512 void pack(const float* src, int64_t plane_stride, int64_t h, int64_t w, float* dst,
                     int64_t dst_w, int64_t y0, int64_t x0) {
  const int64_t n = h * w;
  PixelCursor cur{w, dst_w, y0, x0};
  int64_t i = 0;
  if (dst_w == w) {  // unpadded rows: the destination is one contiguous run of pixels
    float* d = dst + y0 * w * L;
    for (; i + L <= n; i += L) {
      __m512 r[16];
      for (int c = 0; c < 16; ++c) {
        // 16 input streams are more than the hardware prefetcher follows: fetch 4 tiles ahead.
        _mm_prefetch(reinterpret_cast<const char*>(src + c * plane_stride + i + 4 * L),
                     _MM_HINT_T0);
        r[c] = _mm512_loadu_ps(src + c * plane_stride + i);
      }
      transpose16(r);
      for (int p = 0; p < 16; ++p) _mm512_store_ps(d + (i + p) * L, r[p]);
    }
    cur.y += i / w, cur.x += i % w;
  }
  for (; i + L <= n; i += L) {
    __m512 r[16];
    for (int c = 0; c < 16; ++c) {
      _mm_prefetch(reinterpret_cast<const char*>(src + c * plane_stride + i + 4 * L), _MM_HINT_T0);
      r[c] = _mm512_loadu_ps(src + c * plane_stride + i);
    }
    transpose16(r);
    for (int p = 0; p < 16; ++p, cur.next(x0)) _mm512_store_ps(dst + cur.offset(), r[p]);
  }
  for (; i < n; ++i, cur.next(x0)) {
    for (int c = 0; c < 16; ++c) dst[cur.offset() + c] = src[c * plane_stride + i];
  }
}

// h x w channel-interleaved pixels (rows of src_w pixels) back into 16 contiguous planes.
CVD_AVX512 void unpack(const float* src, int64_t src_w, int64_t h, int64_t w, float* dst,
                       int64_t plane_stride) {
  const int64_t n = h * w;
  PixelCursor cur{w, src_w, 0, 0};
  int64_t i = 0;
  if (src_w == w) {  // unpadded rows: one contiguous run of pixels
    for (; i + L <= n; i += L) {
      __m512 r[16];
      for (int p = 0; p < 16; ++p) r[p] = _mm512_load_ps(src + (i + p) * L);
      transpose16(r);
      for (int c = 0; c < 16; ++c) _mm512_storeu_ps(dst + c * plane_stride + i, r[c]);
    }
    cur.y = i / w, cur.x = i % w;
  }
  for (; i + L <= n; i += L) {
    __m512 r[16];
    for (int p = 0; p < 16; ++p, cur.next(0)) r[p] = _mm512_load_ps(src + cur.offset());
    transpose16(r);
    for (int c = 0; c < 16; ++c) _mm512_storeu_ps(dst + c * plane_stride + i, r[c]);
  }
  for (; i < n; ++i, cur.next(0)) {
    for (int c = 0; c < 16; ++c) dst[c * plane_stride + i] = src[cur.offset() + c];
  }
}

// Zeroes everything of an hp x wp pixel buffer outside rows [y0, y0 + h) x columns [x0, x0 + w).
void zero_border(float* buf, int64_t hp, int64_t wp, int64_t y0, int64_t h, int64_t x0, int64_t w) {
  for (int64_t y = 0; y < hp; ++y) {
    float* row = buf + y * wp * L;
    if (y < y0 || y >= y0 + h) {
      std::memset(row, 0, wp * L * sizeof(float));
    } else {
      std::memset(row, 0, x0 * L * sizeof(float));
      std::memset(row + (x0 + w) * L, 0, (wp - x0 - w) * L * sizeof(float));
    }
  }
}

// Channel-interleaved filters of the 16 channels from c: wb[t * 16 + l] = w[(c + l) * taps + t].
void pack_weights(const float* w, int64_t c, int64_t taps, float* wb) {
  for (int64_t t = 0; t < taps; ++t) {
    for (int64_t l = 0; l < L; ++l) wb[t * L + l] = w[(c + l) * taps + t];
  }
}

// ---- Forward ---------------------------------------------------------------------------------

// N output pixels (ox0 .. ox0 + N - 1 of row oy) accumulated in registers over all taps.
template <int N>
CVD_AVX512 inline void forward_accumulate(const DepthwiseGeometry& g, const PaddedInput& pi,
                                          const float* wb, __m512 bias, const float* in, int64_t oy,
                                          int64_t ox0, __m512 (&acc)[N]) {
  const int64_t sw = g.stride_w * L;
#pragma GCC unroll 16
  for (int u = 0; u < N; ++u) acc[u] = bias;
  for (int64_t ky = 0; ky < g.kh; ++ky) {
    const float* irow = in + ((oy * g.stride_h + ky * g.dil_h) * pi.wp + ox0 * g.stride_w) * L;
    for (int64_t kx = 0; kx < g.kw; ++kx) {
      const __m512 wv = _mm512_load_ps(wb + (ky * g.kw + kx) * L);
      const float* ip = irow + kx * g.dil_w * L;
#pragma GCC unroll 16
      for (int u = 0; u < N; ++u) acc[u] = _mm512_fmadd_ps(wv, _mm512_load_ps(ip + u * sw), acc[u]);
    }
  }
}

// N <= 16 pixels of row oy from ox0: accumulated in registers, transposed to 16 channel vectors
// and stored (masked to N pixels) straight into the NCHW planes.
template <int N>
CVD_AVX512 inline void forward_group(const DepthwiseGeometry& g, const PaddedInput& pi,
                                     const float* wb, __m512 bias, const float* in, int64_t oy,
                                     int64_t ox0, float* y, int64_t plane_stride) {
  __m512 part[N];
  forward_accumulate<N>(g, pi, wb, bias, in, oy, ox0, part);
  __m512 acc[L];
#pragma GCC unroll 16
  for (int u = 0; u < L; ++u) acc[u] = u < N ? part[u] : _mm512_setzero_ps();
  transpose16(acc);
  float* out = y + oy * g.ow + ox0;
  const __mmask16 keep = static_cast<__mmask16>((1u << N) - 1);
  for (int c = 0; c < 16; ++c) _mm512_mask_storeu_ps(out + c * plane_stride, keep, acc[c]);
}

// The 16 output planes of one block, each row in groups of 16 pixels plus one shorter group.
CVD_AVX512 void forward_block(const DepthwiseGeometry& g, const PaddedInput& pi, const float* wb,
                              const float* bias, const float* in, float* y, int64_t plane_stride) {
  const __m512 bv = bias ? _mm512_loadu_ps(bias) : _mm512_setzero_ps();
  for (int64_t oy = 0; oy < g.oh; ++oy) {
    int64_t ox = 0;
    for (; ox + L <= g.ow; ox += L) forward_group<L>(g, pi, wb, bv, in, oy, ox, y, plane_stride);
    switch (g.ow - ox) {
      case 15:
        forward_group<15>(g, pi, wb, bv, in, oy, ox, y, plane_stride);
        break;
      case 14:
        forward_group<14>(g, pi, wb, bv, in, oy, ox, y, plane_stride);
        break;
      case 13:
        forward_group<13>(g, pi, wb, bv, in, oy, ox, y, plane_stride);
        break;
      case 12:
        forward_group<12>(g, pi, wb, bv, in, oy, ox, y, plane_stride);
        break;
      case 11:
        forward_group<11>(g, pi, wb, bv, in, oy, ox, y, plane_stride);
        break;
      case 10:
        forward_group<10>(g, pi, wb, bv, in, oy, ox, y, plane_stride);
        break;
      case 9:
        forward_group<9>(g, pi, wb, bv, in, oy, ox, y, plane_stride);
        break;
      case 8:
        forward_group<8>(g, pi, wb, bv, in, oy, ox, y, plane_stride);
        break;
      case 7:
        forward_group<7>(g, pi, wb, bv, in, oy, ox, y, plane_stride);
        break;
      case 6:
        forward_group<6>(g, pi, wb, bv, in, oy, ox, y, plane_stride);
        break;
      case 5:
        forward_group<5>(g, pi, wb, bv, in, oy, ox, y, plane_stride);
        break;
      case 4:
        forward_group<4>(g, pi, wb, bv, in, oy, ox, y, plane_stride);
        break;
      case 3:
        forward_group<3>(g, pi, wb, bv, in, oy, ox, y, plane_stride);
        break;
      case 2:
        forward_group<2>(g, pi, wb, bv, in, oy, ox, y, plane_stride);
        break;
      case 1:
        forward_group<1>(g, pi, wb, bv, in, oy, ox, y, plane_stride);
        break;
      default:
        break;
    }
  }
}

// ---- Backward data (gather form) ----------------------------------------------------------------

// The output-gradient block is packed with `left` / `right` zero columns, so that every output
// column a tap can name for an input pixel is readable.
struct GradLayout {
  int64_t left, right, wg;
};

GradLayout grad_layout(const DepthwiseGeometry& g) {
  GradLayout l;
  l.left = ((g.kw - 1) * g.dil_w) / g.stride_w + 1;
  l.right = std::max<int64_t>(0, (g.w - 1 + g.pad_left) / g.stride_w + 1 - g.ow) + 1;
  l.wg = l.left + g.ow + l.right;
  return l;
}

// The filter taps that reach one input row and one column phase.
struct Taps {
  const int64_t *ky, *row_base;
  int64_t rows;
  const int64_t *kx, *col_off;
  int64_t cols;
};

// N input pixels of one column phase (class indices j0 .. j0 + N - 1) gathered over all taps.
template <int N>
CVD_AVX512 inline void gather_accumulate(const DepthwiseGeometry& g, const Taps& t, const float* wb,
                                         const float* grad, int64_t j0, __m512 (&acc)[N]) {
#pragma GCC unroll 16
  for (int u = 0; u < N; ++u) acc[u] = _mm512_setzero_ps();
  for (int64_t a = 0; a < t.rows; ++a) {
    for (int64_t b = 0; b < t.cols; ++b) {
      const __m512 wv = _mm512_load_ps(wb + (t.ky[a] * g.kw + t.kx[b]) * L);
      const float* gp = grad + (t.row_base[a] + t.col_off[b] + j0) * L;
#pragma GCC unroll 16
      for (int u = 0; u < N; ++u) acc[u] = _mm512_fmadd_ps(wv, _mm512_load_ps(gp + u * L), acc[u]);
    }
  }
}

// Strided column phases: N pixels into a channel-interleaved row buffer (unpacked later).
template <int N>
CVD_AVX512 inline void gather_pixels(const DepthwiseGeometry& g, const Taps& t, const float* wb,
                                     const float* grad, float* orow, int64_t first, int64_t j0) {
  __m512 acc[N];
  gather_accumulate<N>(g, t, wb, grad, j0, acc);
#pragma GCC unroll 8
  for (int u = 0; u < N; ++u) _mm512_store_ps(orow + (first + (j0 + u) * g.stride_w) * L, acc[u]);
}

// Unit stride: N <= 16 consecutive pixels of row iy, transposed and stored (masked) straight
// into the NCHW planes.
template <int N>
CVD_AVX512 inline void gather_group(const DepthwiseGeometry& g, const Taps& t, const float* wb,
                                    const float* grad, int64_t iy, int64_t j0, float* gx,
                                    int64_t plane_stride) {
  __m512 part[N];
  gather_accumulate<N>(g, t, wb, grad, j0, part);
  __m512 acc[L];
#pragma GCC unroll 16
  for (int u = 0; u < L; ++u) acc[u] = u < N ? part[u] : _mm512_setzero_ps();
  transpose16(acc);
  float* out = gx + iy * g.w + j0;
  const __mmask16 keep = static_cast<__mmask16>((1u << N) - 1);
  for (int c = 0; c < 16; ++c) _mm512_mask_storeu_ps(out + c * plane_stride, keep, acc[c]);
}

// The input-gradient planes of one block: straight into the NCHW planes gx for unit stride,
// else into the channel-interleaved buffer `out` (h x w pixels) for the caller to unpack.
CVD_AVX512 void backward_data_block(const DepthwiseGeometry& g, const GradLayout& gl,
                                    const float* wb, const float* grad, float* out, float* gx,
                                    int64_t plane_stride) {
  std::vector<int64_t> row_taps, row_base;  // per input row: filter rows and their grad rows
  std::vector<int64_t> col_taps, col_off;   // per column phase: filter columns and ox offsets
  for (int64_t iy = 0; iy < g.h; ++iy) {
    const int64_t py = iy + g.pad_top;
    row_taps.clear(), row_base.clear();
    for (int64_t ky = 0; ky < g.kh; ++ky) {
      const int64_t t = py - ky * g.dil_h;
      if (t < 0 || t % g.stride_h != 0 || t / g.stride_h >= g.oh) continue;
      row_taps.push_back(ky);
      row_base.push_back((t / g.stride_h) * gl.wg + gl.left);
    }
    float* orow = out + iy * g.w * L;
    for (int64_t rx = 0; rx < g.stride_w; ++rx) {
      // Input columns ix with (ix + pad_left) % stride == rx: first one, count.
      const int64_t first = ((rx - g.pad_left) % g.stride_w + g.stride_w) % g.stride_w;
      if (first >= g.w) continue;
      const int64_t count = (g.w - first + g.stride_w - 1) / g.stride_w;
      col_taps.clear(), col_off.clear();
      for (int64_t kx = 0; kx < g.kw; ++kx) {
        const int64_t t = first + g.pad_left - kx * g.dil_w;
        if (((t % g.stride_w) + g.stride_w) % g.stride_w != 0) continue;
        col_taps.push_back(kx);
        col_off.push_back(t / g.stride_w);  // ox of the class's first column (exact division)
      }
      const Taps taps{row_taps.data(), row_base.data(), static_cast<int64_t>(row_taps.size()),
                      col_taps.data(), col_off.data(),  static_cast<int64_t>(col_taps.size())};
      int64_t j = 0;
      if (g.stride_w == 1) {
        for (; j + L <= count; j += L) gather_group<L>(g, taps, wb, grad, iy, j, gx, plane_stride);
        switch (count - j) {
          case 15:
            gather_group<15>(g, taps, wb, grad, iy, j, gx, plane_stride);
            break;
          case 14:
            gather_group<14>(g, taps, wb, grad, iy, j, gx, plane_stride);
            break;
          case 13:
            gather_group<13>(g, taps, wb, grad, iy, j, gx, plane_stride);
            break;
          case 12:
            gather_group<12>(g, taps, wb, grad, iy, j, gx, plane_stride);
            break;
          case 11:
            gather_group<11>(g, taps, wb, grad, iy, j, gx, plane_stride);
            break;
          case 10:
            gather_group<10>(g, taps, wb, grad, iy, j, gx, plane_stride);
            break;
          case 9:
            gather_group<9>(g, taps, wb, grad, iy, j, gx, plane_stride);
            break;
          case 8:
            gather_group<8>(g, taps, wb, grad, iy, j, gx, plane_stride);
            break;
          case 7:
            gather_group<7>(g, taps, wb, grad, iy, j, gx, plane_stride);
            break;
          case 6:
            gather_group<6>(g, taps, wb, grad, iy, j, gx, plane_stride);
            break;
          case 5:
            gather_group<5>(g, taps, wb, grad, iy, j, gx, plane_stride);
            break;
          case 4:
            gather_group<4>(g, taps, wb, grad, iy, j, gx, plane_stride);
            break;
          case 3:
            gather_group<3>(g, taps, wb, grad, iy, j, gx, plane_stride);
            break;
          case 2:
            gather_group<2>(g, taps, wb, grad, iy, j, gx, plane_stride);
            break;
          case 1:
            gather_group<1>(g, taps, wb, grad, iy, j, gx, plane_stride);
            break;
          default:
            break;
        }
        continue;
      }
      for (; j + U <= count; j += U) gather_pixels<U>(g, taps, wb, grad, orow, first, j);
      switch (count - j) {
        case 7:
          gather_pixels<7>(g, taps, wb, grad, orow, first, j);
          break;
        case 6:
          gather_pixels<6>(g, taps, wb, grad, orow, first, j);
          break;
        case 5:
          gather_pixels<5>(g, taps, wb, grad, orow, first, j);
          break;
        case 4:
          gather_pixels<4>(g, taps, wb, grad, orow, first, j);
          break;
        case 3:
          gather_pixels<3>(g, taps, wb, grad, orow, first, j);
          break;
        case 2:
          gather_pixels<2>(g, taps, wb, grad, orow, first, j);
          break;
        case 1:
          gather_pixels<1>(g, taps, wb, grad, orow, first, j);
          break;
        default:
          break;
      }
    }
  }
}

// ---- Backward weights ---------------------------------------------------------------------------

// Adds the tap sums of one block to acc[(l * taps + t)] (double) and the bias sums to bias[l].
CVD_AVX512 void backward_weight_block(const DepthwiseGeometry& g, const PaddedInput& pi,
                                      const float* in, const float* grad, double* acc,
                                      double* bias) {
  const int64_t taps = g.kh * g.kw, sw = g.stride_w * L;
  alignas(64) double lanes[L];
  for (int64_t t = 0; t < taps; ++t) {
    const int64_t ky = t / g.kw, kx = t % g.kw;
    __m512d lo = _mm512_setzero_pd(), hi = _mm512_setzero_pd();
    for (int64_t oy = 0; oy < g.oh; ++oy) {
      const float* gp = grad + oy * g.ow * L;
      const float* ip = in + ((oy * g.stride_h + ky * g.dil_h) * pi.wp + kx * g.dil_w) * L;
      __m512 a0 = _mm512_setzero_ps(), a1 = a0, a2 = a0, a3 = a0;
      int64_t ox = 0;
      for (; ox + 4 <= g.ow; ox += 4) {
        a0 = _mm512_fmadd_ps(_mm512_load_ps(gp + ox * L), _mm512_load_ps(ip + ox * sw), a0);
        a1 = _mm512_fmadd_ps(_mm512_load_ps(gp + (ox + 1) * L), _mm512_load_ps(ip + (ox + 1) * sw),
                             a1);
        a2 = _mm512_fmadd_ps(_mm512_load_ps(gp + (ox + 2) * L), _mm512_load_ps(ip + (ox + 2) * sw),
                             a2);
        a3 = _mm512_fmadd_ps(_mm512_load_ps(gp + (ox + 3) * L), _mm512_load_ps(ip + (ox + 3) * sw),
                             a3);
      }
      for (; ox < g.ow; ++ox) {
        a0 = _mm512_fmadd_ps(_mm512_load_ps(gp + ox * L), _mm512_load_ps(ip + ox * sw), a0);
      }
      const __m512 row = _mm512_add_ps(_mm512_add_ps(a0, a1), _mm512_add_ps(a2, a3));
      lo = _mm512_add_pd(lo, _mm512_cvtps_pd(_mm512_castps512_ps256(row)));
      hi = _mm512_add_pd(
          hi, _mm512_cvtps_pd(_mm256_castpd_ps(_mm512_extractf64x4_pd(_mm512_castps_pd(row), 1))));
    }
    _mm512_store_pd(lanes, lo);
    _mm512_store_pd(lanes + 8, hi);
    for (int64_t l = 0; l < L; ++l) acc[l * taps + t] += lanes[l];
  }
  if (bias != nullptr) {
    __m512d lo = _mm512_setzero_pd(), hi = _mm512_setzero_pd();
    for (int64_t oy = 0; oy < g.oh; ++oy) {
      __m512 s = _mm512_setzero_ps();
      for (int64_t ox = 0; ox < g.ow; ++ox)
        s = _mm512_add_ps(s, _mm512_load_ps(grad + (oy * g.ow + ox) * L));
      lo = _mm512_add_pd(lo, _mm512_cvtps_pd(_mm512_castps512_ps256(s)));
      hi = _mm512_add_pd(
          hi, _mm512_cvtps_pd(_mm256_castpd_ps(_mm512_extractf64x4_pd(_mm512_castps_pd(s), 1))));
    }
    _mm512_store_pd(lanes, lo);
    _mm512_store_pd(lanes + 8, hi);
    for (int64_t l = 0; l < L; ++l) bias[l] += lanes[l];
  }
}

}  // namespace

bool avx512_supported() { return __builtin_cpu_supports("avx512f"); }

void forward_avx512(const DepthwiseGeometry& g, int64_t c0, int64_t c1, const float* x,
                    const float* w, const float* b, float* y) {
  const PaddedInput pi = padded_input(g);
  const int64_t taps = g.kh * g.kw, blocks = (c1 - c0) / L;
  parallel_ranges(g.n * blocks, g.oh * g.ow * L * taps, [&](int64_t begin, int64_t end) {
    AlignedFloatBuffer in_buf, w_buf;
    float* in = in_buf.get(pi.hp * pi.wp * L);
    float* wb = w_buf.get(taps * L);
    zero_border(in, pi.hp, pi.wp, g.pad_top, g.h, g.pad_left, g.w);
    for (int64_t i = begin; i < end; ++i) {
      const int64_t img = i / blocks, c = c0 + (i % blocks) * L;
      pack_weights(w, c, taps, wb);
      pack(x + (img * g.c + c) * g.h * g.w, g.h * g.w, g.h, g.w, in, pi.wp, g.pad_top, g.pad_left);
      forward_block(g, pi, wb, b ? b + c : nullptr, in, y + (img * g.c + c) * g.oh * g.ow,
                    g.oh * g.ow);
    }
  });
}

void backward_data_avx512(const DepthwiseGeometry& g, int64_t c0, int64_t c1, const float* gy,
                          const float* w, float* gx) {
  const GradLayout gl = grad_layout(g);
  const int64_t taps = g.kh * g.kw, blocks = (c1 - c0) / L;
  parallel_ranges(g.n * blocks, g.oh * g.ow * L * taps, [&](int64_t begin, int64_t end) {
    AlignedFloatBuffer grad_buf, out_buf, w_buf;
    float* grad = grad_buf.get(g.oh * gl.wg * L);
    float* out = out_buf.get(g.h * g.w * L);
    float* wb = w_buf.get(taps * L);
    zero_border(grad, g.oh, gl.wg, 0, g.oh, gl.left, g.ow);
    for (int64_t i = begin; i < end; ++i) {
      const int64_t img = i / blocks, c = c0 + (i % blocks) * L;
      pack_weights(w, c, taps, wb);
      pack(gy + (img * g.c + c) * g.oh * g.ow, g.oh * g.ow, g.oh, g.ow, grad, gl.wg, 0, gl.left);
      float* planes = gx + (img * g.c + c) * g.h * g.w;
      backward_data_block(g, gl, wb, grad, out, planes, g.h * g.w);
      if (g.stride_w > 1) unpack(out, g.w, g.h, g.w, planes, g.h * g.w);
    }
  });
}

void backward_weight_avx512(const DepthwiseGeometry& g, int64_t c0, int64_t c1, const float* gy,
                            const float* x, float* gw, float* gb) {
  const PaddedInput pi = padded_input(g);
  const int64_t taps = g.kh * g.kw, blocks = (c1 - c0) / L, nch = c1 - c0;
  const int slots = max_threads();
  // Per-thread sums: nch * taps weight sums then nch bias sums.
  std::vector<std::vector<double>> sums(static_cast<size_t>(slots));
  const int used = parallel_ranges_indexed(
      g.n * blocks, g.oh * g.ow * L * taps, slots, [&](int t, int64_t begin, int64_t end) {
        std::vector<double>& s = sums[static_cast<size_t>(t)];
        s.assign(static_cast<size_t>(nch * (taps + 1)), 0.0);
        AlignedFloatBuffer in_buf, grad_buf;
        float* in = in_buf.get(pi.hp * pi.wp * L);
        float* grad = grad_buf.get(g.oh * g.ow * L);
        zero_border(in, pi.hp, pi.wp, g.pad_top, g.h, g.pad_left, g.w);
        for (int64_t i = begin; i < end; ++i) {
          const int64_t img = i / blocks, cb = i % blocks, c = c0 + cb * L;
          pack(x + (img * g.c + c) * g.h * g.w, g.h * g.w, g.h, g.w, in, pi.wp, g.pad_top,
               g.pad_left);
          pack(gy + (img * g.c + c) * g.oh * g.ow, g.oh * g.ow, g.oh, g.ow, grad, g.ow, 0, 0);
          backward_weight_block(g, pi, in, grad, s.data() + cb * L * taps,
                                gb ? s.data() + nch * taps + cb * L : nullptr);
        }
      });
  for (int64_t c = 0; c < nch; ++c) {
    for (int64_t t = 0; t < taps; ++t) {
      double v = 0.0;
      for (int k = 0; k < used; ++k) v += sums[static_cast<size_t>(k)][c * taps + t];
      gw[(c0 + c) * taps + t] = static_cast<float>(v);
    }
    if (gb) {
      double v = 0.0;
      for (int k = 0; k < used; ++k) v += sums[static_cast<size_t>(k)][nch * taps + c];
      gb[c0 + c] = static_cast<float>(v);
    }
  }
}

}  // namespace cvd::cpu::depthwise

#else  // no x86-64 GCC-compatible compiler: the portable implementation serves every channel

namespace cvd::cpu::depthwise {
bool avx512_supported() { return false; }
void forward_avx512(const DepthwiseGeometry&, int64_t, int64_t, const float*, const float*,
                    const float*, float*) {}
void backward_data_avx512(const DepthwiseGeometry&, int64_t, int64_t, const float*, const float*,
                          float*) {}
void backward_weight_avx512(const DepthwiseGeometry&, int64_t, int64_t, const float*, const float*,
                            float*, float*) {}
}  // namespace cvd::cpu::depthwise

#endif
