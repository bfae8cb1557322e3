// AVX-512 depthwise convolution straight on the NCHW planes (see depthwise_conv2d_kernels.h):
// forward and backward data, one (image, channel) plane at a time, no transposes.
//
// Both passes are written as stride-1 correlations over zero-padded "source" planes that share a
// row pitch: out[r][c] = bias + sum over taps of w_t * src_t[r + dy_t][c + dx_t].
//   forward:       the sources are the stride phases of the input plane (phase (ry, rx) holds
//                  x[a * sh + ry][b * sw + rx]); one output grid, the output plane.
//   backward data: the source is the output-gradient plane; one output grid per stride phase of
//                  the input gradient, each from the filter taps of matching parity; the phases
//                  are interleaved back into the plane.
// The taps of a grid are grouped by (source plane, dx), each group a run of up to 8 consecutive
// dy. A band of up to 16 output rows x 16 columns is accumulated in registers: for each group,
// each source row the band needs is loaded once and multiplied into every output row it feeds
// (a 5-tap column: 20 loads for 80 multiply-adds on a 16-row band), the group's weights held in
// registers. The loads are unaligned, so they, not the multiply-adds, are what to save.
// Stride-2 phases are split and interleaved with two-vector permutes; other strides copy
// element by element. Every stride is correct; the library sends only unit stride here (at
// stride 2 the blocked implementation is faster, see depthwise_conv2d.cpp). Compiled with a
// target attribute; only called when the CPU has AVX-512F.
#include <immintrin.h>

#include <algorithm>
#include <cstring>
#include <vector>

#include "kernels/cpu/cpu_parallel.h"
#include "kernels/cpu/depthwise_conv2d_kernels.h"

#if defined(__GNUC__) && defined(__x86_64__)

#define CVD_AVX512 __attribute__((target("avx512f")))

namespace cvd::cpu::depthwise {

// Named, so that a unity build can merge this file with the blocked implementation.
namespace direct {

constexpr int64_t L = 16;  // floats per vector

int64_t floor_div(int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

// A tap: source plane, offset of the source pixel from the output pixel, filter index.
struct Tap {
  int64_t plane, dy, dx, k;
};

constexpr int kMaxRun = 8;  // dy values per tap group

// Taps of one source plane and dx at dy0 .. dy0 + m - 1 (filter index k[t], -1: none).
struct TapGroup {
  int64_t plane, dx, dy0;
  int64_t k[kMaxRun];
};

// One output grid (rows x cols), the taps that read into it, and their groups, all padded to
// the same run length m (so that one compiled loop serves every group).
struct Grid {
  int64_t rows = 0, cols = 0, m = 0;
  std::vector<Tap> taps;
  std::vector<TapGroup> groups;
};

// Stacked zero-padded source planes: data pixel (a, b) of plane p at
// p * plane_size + (top + a) * pitch + left + b.
struct Plan {
  int64_t planes = 0, top = 0, left = 0, pitch = 0, rows = 0;
  std::vector<int64_t> src_rows, src_cols;  // data size of each source plane
  std::vector<Grid> grids;
  int64_t plane_size() const { return rows * pitch; }
  int64_t out_size() const {
    int64_t n = 0;
    for (const Grid& g : grids) n = std::max(n, g.rows * pitch);
    return n;
  }
};

// Groups a grid's taps by (plane, dx) into runs of consecutive dy, all of the longest length.
void group_taps(Grid& g) {
  std::vector<Tap> taps = g.taps;
  std::sort(taps.begin(), taps.end(), [](const Tap& a, const Tap& b) {
    return a.plane != b.plane ? a.plane < b.plane : a.dx != b.dx ? a.dx < b.dx : a.dy < b.dy;
  });
  g.groups.clear();
  g.m = 0;
  for (const Tap& t : taps) {
    TapGroup* last = g.groups.empty() ? nullptr : &g.groups.back();
    if (last == nullptr || last->plane != t.plane || last->dx != t.dx ||
        t.dy - last->dy0 >= kMaxRun) {
      g.groups.push_back({t.plane, t.dx, t.dy, {}});
      last = &g.groups.back();
      std::fill(last->k, last->k + kMaxRun, int64_t{-1});
    }
    last->k[t.dy - last->dy0] = t.k;
    g.m = std::max(g.m, t.dy - last->dy0 + 1);
  }
}

// Groups the taps, then fills in the padding and pitch.
void finish_plan(Plan& p) {
  int64_t min_dy = 0, min_dx = 0, max_dy = 0, max_dx = 0;
  for (Grid& g : p.grids) {
    group_taps(g);
    for (const TapGroup& t : g.groups) {
      min_dy = std::min(min_dy, t.dy0), max_dy = std::max(max_dy, t.dy0 + g.m - 1);
      min_dx = std::min(min_dx, t.dx), max_dx = std::max(max_dx, t.dx);
    }
  }
  p.top = -min_dy, p.left = -min_dx;
  int64_t data_rows = 0, data_cols = 0, out_rows = 0, out_cols = 0;
  for (int64_t i = 0; i < p.planes; ++i) {
    data_rows = std::max(data_rows, p.src_rows[i]);
    data_cols = std::max(data_cols, p.src_cols[i]);
  }
  for (const Grid& g : p.grids) {
    out_rows = std::max(out_rows, g.rows), out_cols = std::max(out_cols, g.cols);
  }
  // Every kept output column reads inside its own source row; the data fits in a row.
  p.pitch = std::max(p.left + data_cols, out_cols + p.left + max_dx);
  // Plus at least one row and 16 floats: a band's last vector may read past its row, and the
  // stride-2 split writes up to 15 zeros past a row.
  p.rows = std::max(p.top + data_rows, out_rows + p.top + max_dy) +
           std::max<int64_t>(1, (L + p.pitch - 1) / p.pitch);
}

// Number of indices i in [0, n) with i % s == r.
int64_t phase_count(int64_t n, int64_t s, int64_t r) { return r < n ? (n - r + s - 1) / s : 0; }

Plan forward_plan(const DepthwiseGeometry& g) {
  Plan p;
  p.planes = g.stride_h * g.stride_w;
  for (int64_t ry = 0; ry < g.stride_h; ++ry) {
    for (int64_t rx = 0; rx < g.stride_w; ++rx) {
      p.src_rows.push_back(phase_count(g.h, g.stride_h, ry));
      p.src_cols.push_back(phase_count(g.w, g.stride_w, rx));
    }
  }
  Grid out;
  out.rows = g.oh, out.cols = g.ow;
  for (int64_t ky = 0; ky < g.kh; ++ky) {
    for (int64_t kx = 0; kx < g.kw; ++kx) {
      // Input row of output row oy: oy * sh + ky * dh - pad_top = (oy + dy) * sh + ry.
      const int64_t oy = ky * g.dil_h - g.pad_top, ox = kx * g.dil_w - g.pad_left;
      const int64_t dy = floor_div(oy, g.stride_h), dx = floor_div(ox, g.stride_w);
      const int64_t ry = oy - dy * g.stride_h, rx = ox - dx * g.stride_w;
      out.taps.push_back({ry * g.stride_w + rx, dy, dx, ky * g.kw + kx});
    }
  }
  p.grids.push_back(std::move(out));
  finish_plan(p);
  return p;
}

// Grid ry * sw + rx holds input-gradient pixels (a * sh + ry, b * sw + rx).
Plan backward_data_plan(const DepthwiseGeometry& g) {
  Plan p;
  p.planes = 1;
  p.src_rows = {g.oh}, p.src_cols = {g.ow};
  for (int64_t ry = 0; ry < g.stride_h; ++ry) {
    for (int64_t rx = 0; rx < g.stride_w; ++rx) {
      Grid grid;
      grid.rows = phase_count(g.h, g.stride_h, ry), grid.cols = phase_count(g.w, g.stride_w, rx);
      // Input row a * sh + ry is read by output row oy through filter row ky when
      // oy * sh + ky * dh - pad_top == a * sh + ry, i.e. oy = a + (ry + pad_top - ky * dh) / sh.
      for (int64_t ky = 0; ky < g.kh; ++ky) {
        const int64_t ny = ry + g.pad_top - ky * g.dil_h;
        if (ny - floor_div(ny, g.stride_h) * g.stride_h != 0) continue;
        for (int64_t kx = 0; kx < g.kw; ++kx) {
          const int64_t nx = rx + g.pad_left - kx * g.dil_w;
          if (nx - floor_div(nx, g.stride_w) * g.stride_w != 0) continue;
          grid.taps.push_back({0, ny / g.stride_h, nx / g.stride_w, ky * g.kw + kx});
        }
      }
      p.grids.push_back(std::move(grid));
    }
  }
  finish_plan(p);
  return p;
}

// A zeroed 64-byte aligned buffer of n floats (the zero padding of the source planes).
float* zeroed(AlignedFloatBuffer& buffer, int64_t n) {
  float* p = buffer.get(n);
  std::memset(p, 0, static_cast<size_t>(n) * sizeof(float));
  return p;
}

inline __mmask16 first_lanes(int64_t n) {
  return n >= L ? static_cast<__mmask16>(0xffff) : static_cast<__mmask16>((1u << n) - 1);
}

#define CVD_AVX512_INLINE __attribute__((target("avx512f"), always_inline)) inline

// acc[r] += sum_t w[t] * row (r + t) of s (rows `pitch` apart), each row loaded once.
template <int R, int M>
CVD_AVX512_INLINE void accumulate_run(const float* s, int64_t pitch, const float* w,
                                      __m512 (&acc)[R]) {
  __m512 wv[M];
#pragma GCC unroll 8
  for (int t = 0; t < M; ++t) wv[t] = _mm512_set1_ps(w[t]);
#pragma GCC unroll 24
  for (int j = 0; j < R + M - 1; ++j) {
    __m512 v = _mm512_loadu_ps(s + j * pitch);
    // Keeps v in a register: GCC would otherwise fold the load into each multiply-add that
    // uses it, loading (unaligned) the same row up to M times.
    asm("" : "+v"(v));
#pragma GCC unroll 8
    for (int t = 0; t < M; ++t) {
      const int r = j - t;
      if (r >= 0 && r < R) acc[r] = _mm512_fmadd_ps(v, wv[t], acc[r]);
    }
  }
}

// Output rows o0 .. o0 + R - 1 of a grid whose groups have M taps, every column, into dst (rows
// dst_pitch apart). wg: the weights of each group (kMaxRun per group, 0 where it has no tap).
template <int R, int M>
CVD_AVX512 void correlate_band(const Plan& p, const Grid& grid, const float* src, const float* wg,
                               float bias, int64_t o0, float* dst, int64_t dst_pitch) {
  for (int64_t c = 0; c < grid.cols; c += L) {
    __m512 acc[R];
#pragma GCC unroll 16
    for (int r = 0; r < R; ++r) acc[r] = _mm512_set1_ps(bias);
    for (size_t i = 0; i < grid.groups.size(); ++i) {
      const TapGroup& t = grid.groups[i];
      const float* s =
          src + t.plane * p.plane_size() + (p.top + o0 + t.dy0) * p.pitch + p.left + c + t.dx;
      accumulate_run<R, M>(s, p.pitch, wg + i * kMaxRun, acc);
    }
    if (c + L <= grid.cols) {
#pragma GCC unroll 16
      for (int r = 0; r < R; ++r) _mm512_storeu_ps(dst + (o0 + r) * dst_pitch + c, acc[r]);
    } else {
      const __mmask16 keep = first_lanes(grid.cols - c);
#pragma GCC unroll 16
      for (int r = 0; r < R; ++r)
        _mm512_mask_storeu_ps(dst + (o0 + r) * dst_pitch + c, keep, acc[r]);
    }
  }
}

// The whole grid: bands of 16 rows, the rest in bands of 8, 4, 2, 1.
template <int M>
CVD_AVX512 void correlate_rows(const Plan& p, const Grid& grid, const float* src, const float* w,
                               float bias, float* dst, int64_t dst_pitch) {
  int64_t o = 0;
  for (; o + 16 <= grid.rows; o += 16) {
    correlate_band<16, M>(p, grid, src, w, bias, o, dst, dst_pitch);
  }
  if (grid.rows - o >= 8) correlate_band<8, M>(p, grid, src, w, bias, o, dst, dst_pitch), o += 8;
  if (grid.rows - o >= 4) correlate_band<4, M>(p, grid, src, w, bias, o, dst, dst_pitch), o += 4;
  if (grid.rows - o >= 2) correlate_band<2, M>(p, grid, src, w, bias, o, dst, dst_pitch), o += 2;
  if (grid.rows - o >= 1) correlate_band<1, M>(p, grid, src, w, bias, o, dst, dst_pitch);
}

// dst (rows dst_pitch apart) = bias + the grid's correlation, wg: the group weights of one
// channel (group_weights).
CVD_AVX512 void correlate(const Plan& p, const Grid& grid, const float* src, const float* wg,
                          float bias, float* dst, int64_t dst_pitch) {
  using Rows =
      void (*)(const Plan&, const Grid&, const float*, const float*, float, float*, int64_t);
  // By run length; 0 (no taps: the bias alone) runs as 1 with zero weights.
  static constexpr Rows by_run[kMaxRun + 1] = {
      correlate_rows<1>, correlate_rows<1>, correlate_rows<2>, correlate_rows<3>, correlate_rows<4>,
      correlate_rows<5>, correlate_rows<6>, correlate_rows<7>, correlate_rows<8>};
  by_run[grid.m](p, grid, src, wg, bias, dst, dst_pitch);
}

// The group weights of every grid for channels [c0, c1): channel c's for grid k start at
// ((c - c0) * grids + k) * stride, where stride = group_weights_stride(p).
int64_t group_weights_stride(const Plan& p) {
  size_t groups = 0;
  for (const Grid& g : p.grids) groups = std::max(groups, g.groups.size());
  return static_cast<int64_t>(groups) * kMaxRun;
}

std::vector<float> group_weights(const Plan& p, const float* w, int64_t taps, int64_t c0,
                                 int64_t c1) {
  const int64_t stride = group_weights_stride(p), grids = static_cast<int64_t>(p.grids.size());
  std::vector<float> out(static_cast<size_t>((c1 - c0) * grids * stride), 0.0f);
  for (int64_t c = c0; c < c1; ++c) {
    for (int64_t k = 0; k < grids; ++k) {
      float* dst = out.data() + ((c - c0) * grids + k) * stride;
      const std::vector<TapGroup>& groups = p.grids[k].groups;
      for (size_t i = 0; i < groups.size(); ++i) {
        for (int t = 0; t < kMaxRun; ++t) {
          if (groups[i].k[t] >= 0) dst[i * kMaxRun + t] = w[c * taps + groups[i].k[t]];
        }
      }
    }
  }
  return out;
}

// Permutes: even and odd lanes of the 32 floats in (lo, hi), and their inverse (interleave).
CVD_AVX512 inline __m512i even_lanes() {
  return _mm512_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30);
}
CVD_AVX512 inline __m512i interleave_lanes(int half) {
  return half == 0
             ? _mm512_setr_epi32(0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23)
             : _mm512_setr_epi32(8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31);
}

// Loads row[i, i + 16) and zeros past row[n).
CVD_AVX512 inline __m512 load_upto(const float* row, int64_t i, int64_t n) {
  return i + L <= n ? _mm512_loadu_ps(row + i)
                    : _mm512_maskz_loadu_ps(first_lanes(std::max<int64_t>(n - i, 0)), row + i);
}

// Stores v into row[i, i + 16), up to row[n).
CVD_AVX512 inline void store_upto(float* row, int64_t i, int64_t n, __m512 v) {
  if (i + L <= n) {
    _mm512_storeu_ps(row + i, v);
  } else if (i < n) {
    _mm512_mask_storeu_ps(row + i, first_lanes(n - i), v);
  }
}

// Splits row[0, n) into even (row[2b]) and odd (row[2b + 1]) elements, written in whole vectors:
// up to 15 zeros past the last of each (the caller's rows have room for them).
CVD_AVX512 void split_pairs(const float* row, int64_t n, float* even, float* odd) {
  const __m512i ie = even_lanes(), io = _mm512_add_epi32(ie, _mm512_set1_epi32(1));
  for (int64_t b = 0; 2 * b < n; b += L) {
    const __m512 lo = load_upto(row, 2 * b, n), hi = load_upto(row, 2 * b + L, n);
    _mm512_storeu_ps(even + b, _mm512_permutex2var_ps(lo, ie, hi));
    _mm512_storeu_ps(odd + b, _mm512_permutex2var_ps(lo, io, hi));
  }
}

// row[2b] = even[b], row[2b + 1] = odd[b] for 2b (+ 1) < n (even and odd readable in whole
// vectors).
CVD_AVX512 void interleave_pairs(const float* even, const float* odd, int64_t n, float* row) {
  const __m512i i0 = interleave_lanes(0), i1 = interleave_lanes(1);
  for (int64_t b = 0; 2 * b < n; b += L) {
    const __m512 e = _mm512_loadu_ps(even + b), o = _mm512_loadu_ps(odd + b);
    store_upto(row, 2 * b, n, _mm512_permutex2var_ps(e, i0, o));
    store_upto(row, 2 * b + L, n, _mm512_permutex2var_ps(e, i1, o));
  }
}

// Copies plane x [h, w] into the stride phases of the (pre-zeroed) source planes.
CVD_AVX512 void load_phases(const DepthwiseGeometry& g, const Plan& p, const float* x, float* src) {
  for (int64_t ry = 0; ry < g.stride_h; ++ry) {
    float* dst = src + ry * g.stride_w * p.plane_size() + p.top * p.pitch + p.left;
    for (int64_t iy = ry; iy < g.h; iy += g.stride_h, dst += p.pitch) {
      const float* row = x + iy * g.w;
      if (g.stride_w == 1) {
        std::memcpy(dst, row, g.w * sizeof(float));
      } else if (g.stride_w == 2) {
        split_pairs(row, g.w, dst, dst + p.plane_size());
      } else {
        for (int64_t ix = 0; ix < g.w; ++ix) {
          dst[(ix % g.stride_w) * p.plane_size() + ix / g.stride_w] = row[ix];
        }
      }
    }
  }
}

// Writes the phase grids (grid ry * sw + rx at out + that * grid_stride, rows of `pitch`)
// into plane gx [h, w].
CVD_AVX512 void store_phases(const DepthwiseGeometry& g, const Plan& p, const float* out,
                             int64_t grid_stride, float* gx) {
  for (int64_t iy = 0; iy < g.h; ++iy) {
    const int64_t ry = iy % g.stride_h, a = iy / g.stride_h;
    const float* rows = out + ry * g.stride_w * grid_stride + a * p.pitch;
    float* dst = gx + iy * g.w;
    if (g.stride_w == 1) {
      std::memcpy(dst, rows, g.w * sizeof(float));
    } else if (g.stride_w == 2) {
      interleave_pairs(rows, rows + grid_stride, g.w, dst);
    } else {
      for (int64_t ix = 0; ix < g.w; ++ix) {
        dst[ix] = rows[(ix % g.stride_w) * grid_stride + ix / g.stride_w];
      }
    }
  }
}

}  // namespace direct

using direct::Grid;
using direct::Plan;

void forward_direct_avx512(const DepthwiseGeometry& g, int64_t c0, int64_t c1, const float* x,
                           const float* w, const float* b, float* y) {
  const Plan p = direct::forward_plan(g);
  const Grid& grid = p.grids[0];
  const int64_t taps = g.kh * g.kw, nc = c1 - c0, wstride = direct::group_weights_stride(p);
  const std::vector<float> wg = direct::group_weights(p, w, taps, c0, c1);
  parallel_ranges(g.n * nc, g.oh * g.ow * taps, [&](int64_t begin, int64_t end) {
    // Slack past the last plane: a band's last vector may read past its row.
    AlignedFloatBuffer src_buf;
    float* src = direct::zeroed(src_buf, p.planes * p.plane_size() + p.pitch + direct::L);
    for (int64_t i = begin; i < end; ++i) {
      const int64_t c = c0 + i % nc, plane = (i / nc) * g.c + c;
      direct::load_phases(g, p, x + plane * g.h * g.w, src);
      direct::correlate(p, grid, src, wg.data() + (c - c0) * wstride, b ? b[c] : 0.0f,
                        y + plane * g.oh * g.ow, g.ow);
    }
  });
}

void backward_data_direct_avx512(const DepthwiseGeometry& g, int64_t c0, int64_t c1,
                                 const float* gy, const float* w, float* gx) {
  const Plan p = direct::backward_data_plan(g);
  const int64_t taps = g.kh * g.kw, nc = c1 - c0, grid_stride = p.out_size();
  const int64_t grids = static_cast<int64_t>(p.grids.size());
  const int64_t wstride = direct::group_weights_stride(p);
  const std::vector<float> wg = direct::group_weights(p, w, taps, c0, c1);
  parallel_ranges(g.n * nc, g.h * g.w * taps, [&](int64_t begin, int64_t end) {
    AlignedFloatBuffer src_buf, out_buf;
    float* src = direct::zeroed(src_buf, p.plane_size() + p.pitch + direct::L);
    float* out = out_buf.get(grids * grid_stride + direct::L);
    const bool unit_stride = g.stride_h == 1 && g.stride_w == 1;
    for (int64_t i = begin; i < end; ++i) {
      const int64_t c = c0 + i % nc, plane = (i / nc) * g.c + c;
      const float* gplane = gy + plane * g.oh * g.ow;
      for (int64_t oy = 0; oy < g.oh; ++oy) {
        std::memcpy(src + (p.top + oy) * p.pitch + p.left, gplane + oy * g.ow,
                    g.ow * sizeof(float));
      }
      if (unit_stride) {  // one grid: the input-gradient plane itself
        direct::correlate(p, p.grids[0], src, wg.data() + (c - c0) * wstride, 0.0f,
                          gx + plane * g.h * g.w, g.w);
        continue;
      }
      for (int64_t k = 0; k < grids; ++k) {
        direct::correlate(p, p.grids[k], src, wg.data() + ((c - c0) * grids + k) * wstride, 0.0f,
                          out + k * grid_stride, p.pitch);
      }
      direct::store_phases(g, p, out, grid_stride, gx + plane * g.h * g.w);
    }
  });
}

}  // namespace cvd::cpu::depthwise

#else  // no x86-64 GCC-compatible compiler: never called (avx512_supported() is false)

namespace cvd::cpu::depthwise {
void forward_direct_avx512(const DepthwiseGeometry&, int64_t, int64_t, const float*, const float*,
                           const float*, float*) {}
void backward_data_direct_avx512(const DepthwiseGeometry&, int64_t, int64_t, const float*,
                                 const float*, float*) {}
}  // namespace cvd::cpu::depthwise

#endif
