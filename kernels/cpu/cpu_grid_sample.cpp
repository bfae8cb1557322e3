// OpenMP f32 kernels of bilinear grid_sample (PyTorch semantics: zeros or border padding, both
// align_corners modes), forward and backward. The coordinate math is the shared
// engine/resample_math.h (grid_source_coord); corner weights follow PyTorch's expressions.
// Work is done in chunks of grid points: the taps of a chunk (4 clamped offsets, weights and
// in-image masks, structure of arrays) are computed once and reused for every channel.
//   forward: parallel over (image, chunk of points), all channels per task.
//   backward, race-free without atomics, in two passes:
//     ggrid: parallel over (image, chunk of points); a task sums over all channels for its
//       points and writes only their ggrid entries;
//     gx: parallel over (image, block of channels); a task scatters every point of its image
//       into its own channel planes only. With fewer planes than threads, threads instead take
//       ranges of points and scatter into private copies of gx that are summed afterwards.
#include <algorithm>
#include <cmath>
#include <memory>
#include <vector>

#include "engine/resample_math.h"
#include "kernels/cpu/cpu_openmp_families.h"
#include "kernels/cpu/cpu_parallel.h"

namespace cvd::cpu {

namespace {

constexpr int64_t kChunk = 512;  // grid points per task chunk

// The bilinear taps of a chunk of grid points, structure of arrays. Corners: 0 nw, 1 ne, 2 sw,
// 3 se.
struct ChunkTaps {
  int32_t off[4][kChunk];  // offset in the plane, clamped into the image
  float w[4][kChunk];      // bilinear weight, 0 for corners outside the image
  // Backward only:
  float inside[4][kChunk];  // 1 for corners inside the image, 0 outside
  float wx0[kChunk], wx1[kChunk], wy0[kChunk], wy1[kChunk];  // x1 - ix, ix - x0, y1 - iy, iy - y0
  float dx[kChunk], dy[kChunk];                              // d(pixel coordinate) / d(grid value)
};

struct GridGeometry {
  int64_t n, c, h, w, points;  // points = OH * OW
};

GridGeometry grid_geometry(const Tensor& x, const Tensor& grid, const Tensor& y) {
  for (const Tensor* t : {&x, &grid, &y}) {
    CVD_ASSERT(t->defined() && t->device().is_cpu() && t->dtype() == DType::f32);
    CVD_ASSERT(t->is_contiguous() && t->dim() == 4);
  }
  CVD_ASSERT(grid.shape()[3] == 2 && grid.shape()[0] == x.shape()[0]);
  CVD_ASSERT(y.shape()[0] == x.shape()[0] && y.shape()[1] == x.shape()[1]);
  CVD_ASSERT(y.shape()[2] == grid.shape()[1] && y.shape()[3] == grid.shape()[2]);
  CVD_ASSERT(x.shape()[2] >= 1 && x.shape()[3] >= 1);
  CVD_ASSERT(x.shape()[2] * x.shape()[3] < (int64_t{1} << 30));
  return {x.shape()[0], x.shape()[1], x.shape()[2], x.shape()[3], y.shape()[2] * y.shape()[3]};
}

// One axis of a grid point: the lower corner index `i0` (floor of the pixel coordinate), the
// weights of i0 and i0 + 1 and whether each is inside [0, size), and d(coordinate)/dg.
struct AxisTap {
  int32_t i0;
  float w0, w1, in0, in1, d;
};

template <GridPadding PAD, bool AC>
inline AxisTap axis_tap(float g, int32_t size) {
  AxisTap t;
  float c = grid_source_coord<float>(g, size, PAD, AC, &t.d);
  // NaN samples nothing; far outside, every corner is outside either way, and clamping keeps
  // the integers in range.
  c = c == c ? c : -2.0f;
  c = std::min(std::max(c, -2.0f), static_cast<float>(size + 1));
  int32_t i0 = static_cast<int32_t>(c);  // truncation, then floor for negative values
  i0 -= static_cast<float>(i0) > c ? 1 : 0;
  const float f0 = static_cast<float>(i0);
  t.i0 = i0;
  t.w0 = (f0 + 1.0f) - c;  // PyTorch: ix_se - ix
  t.w1 = c - f0;           // PyTorch: ix - ix_nw
  t.in0 = static_cast<float>((i0 >= 0) & (i0 < size));
  t.in1 = static_cast<float>((i0 + 1 >= 0) & (i0 + 1 < size));
  return t;
}

// Taps of points [p0, p0 + count) of image n; the backward fields only when GRAD.
template <GridPadding PAD, bool AC, bool GRAD>
void chunk_taps_impl(const float* grid, const GridGeometry& g, int64_t n, int64_t p0, int64_t count,
                     ChunkTaps& t) {
  const float* gp = grid + (n * g.points + p0) * 2;
  const int32_t w = static_cast<int32_t>(g.w), h = static_cast<int32_t>(g.h);
  for (int64_t i = 0; i < count; ++i) {
    const AxisTap ax = axis_tap<PAD, AC>(gp[2 * i], w);
    const AxisTap ay = axis_tap<PAD, AC>(gp[2 * i + 1], h);
    const int32_t c0 = std::min(std::max(ax.i0, 0), w - 1);
    const int32_t c1 = std::min(std::max(ax.i0 + 1, 0), w - 1);
    const int32_t r0 = std::min(std::max(ay.i0, 0), h - 1) * w;
    const int32_t r1 = std::min(std::max(ay.i0 + 1, 0), h - 1) * w;
    const float m[4] = {ax.in0 * ay.in0, ax.in1 * ay.in0, ax.in0 * ay.in1, ax.in1 * ay.in1};
    t.off[0][i] = r0 + c0, t.off[1][i] = r0 + c1, t.off[2][i] = r1 + c0, t.off[3][i] = r1 + c1;
    t.w[0][i] = m[0] * (ax.w0 * ay.w0);
    t.w[1][i] = m[1] * (ax.w1 * ay.w0);
    t.w[2][i] = m[2] * (ax.w0 * ay.w1);
    t.w[3][i] = m[3] * (ax.w1 * ay.w1);
    if constexpr (GRAD) {
      for (int k = 0; k < 4; ++k) t.inside[k][i] = m[k];
      t.wx0[i] = ax.w0, t.wx1[i] = ax.w1, t.wy0[i] = ay.w0, t.wy1[i] = ay.w1;
      t.dx[i] = ax.d, t.dy[i] = ay.d;
    }
  }
}

template <bool GRAD>
void chunk_taps(const float* grid, const GridGeometry& g, int64_t n, int64_t p0, int64_t count,
                const GridSampleParams& p, ChunkTaps& t) {
  constexpr GridPadding kBorder = GridPadding::border, kZeros = GridPadding::zeros;
  if (p.padding == kBorder) {
    if (p.align_corners) return chunk_taps_impl<kBorder, true, GRAD>(grid, g, n, p0, count, t);
    return chunk_taps_impl<kBorder, false, GRAD>(grid, g, n, p0, count, t);
  }
  if (p.align_corners) return chunk_taps_impl<kZeros, true, GRAD>(grid, g, n, p0, count, t);
  return chunk_taps_impl<kZeros, false, GRAD>(grid, g, n, p0, count, t);
}

// in {x [N,C,H,W], grid [N,OH,OW,2]}, out {y [N,C,OH,OW]}; GridSampleParams.
void grid_sample(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 2 && a.out.size() == 1 && a.params != nullptr);
  const Tensor& x = a.in[0];
  const Tensor& grid = a.in[1];
  const Tensor& y = a.out[0];
  const GridSampleParams& p = a.p<GridSampleParams>();
  const GridGeometry g = grid_geometry(x, grid, y);
  const float* xp = x.data<float>();
  const float* gp = grid.data<float>();
  float* yp = y.data<float>();
  const int64_t chunks = (g.points + kChunk - 1) / kChunk;
  parallel_ranges(g.n * chunks, kChunk * (g.c * 8 + 30), [&](int64_t b, int64_t e) {
    auto taps = std::make_unique<ChunkTaps>();
    const ChunkTaps& t = *taps;
    for (int64_t task = b; task < e; ++task) {
      const int64_t n = task / chunks, p0 = (task % chunks) * kChunk;
      const int64_t count = std::min(kChunk, g.points - p0);
      chunk_taps<false>(gp, g, n, p0, count, p, *taps);
      for (int64_t c = 0; c < g.c; ++c) {
        const float* plane = xp + (n * g.c + c) * g.h * g.w;
        float* out = yp + (n * g.c + c) * g.points + p0;
        for (int64_t i = 0; i < count; ++i) {
          out[i] = plane[t.off[0][i]] * t.w[0][i] + plane[t.off[1][i]] * t.w[1][i] +
                   plane[t.off[2][i]] * t.w[2][i] + plane[t.off[3][i]] * t.w[3][i];
        }
      }
    }
  });
}

// ggrid for all points: sum over channels of gy times the derivative of the sample.
void grid_sample_grad_grid(const float* gyp, const float* xp, const float* gp, float* ggp,
                           const GridGeometry& g, const GridSampleParams& p) {
  const int64_t chunks = (g.points + kChunk - 1) / kChunk;
  parallel_ranges(g.n * chunks, kChunk * (g.c * 12 + 30), [&](int64_t b, int64_t e) {
    auto taps = std::make_unique<ChunkTaps>();
    const ChunkTaps& t = *taps;
    std::vector<float> gix(kChunk), giy(kChunk);
    for (int64_t task = b; task < e; ++task) {
      const int64_t n = task / chunks, p0 = (task % chunks) * kChunk;
      const int64_t count = std::min(kChunk, g.points - p0);
      chunk_taps<true>(gp, g, n, p0, count, p, *taps);
      std::fill(gix.begin(), gix.begin() + count, 0.0f);
      std::fill(giy.begin(), giy.begin() + count, 0.0f);
      for (int64_t c = 0; c < g.c; ++c) {
        const float* plane = xp + (n * g.c + c) * g.h * g.w;
        const float* go = gyp + (n * g.c + c) * g.points + p0;
        for (int64_t i = 0; i < count; ++i) {
          const float nw = t.inside[0][i] * plane[t.off[0][i]];
          const float ne = t.inside[1][i] * plane[t.off[1][i]];
          const float sw = t.inside[2][i] * plane[t.off[2][i]];
          const float se = t.inside[3][i] * plane[t.off[3][i]];
          gix[i] += go[i] * ((ne - nw) * t.wy0[i] + (se - sw) * t.wy1[i]);
          giy[i] += go[i] * ((sw - nw) * t.wx0[i] + (se - ne) * t.wx1[i]);
        }
      }
      float* out = ggp + (n * g.points + p0) * 2;
      for (int64_t i = 0; i < count; ++i) {
        out[2 * i] = gix[i] * t.dx[i];
        out[2 * i + 1] = giy[i] * t.dy[i];
      }
    }
  });
}

// Scatters gy of points [p0, p1) of image n, channels [c0, c1), into gx planes at `gx_n`
// (the planes of image n).
void scatter_points(const float* gyp, const float* gp, float* gx_n, const GridGeometry& g,
                    const GridSampleParams& p, int64_t n, int64_t c0, int64_t c1, int64_t p0,
                    int64_t p1, ChunkTaps& t) {
  for (int64_t q0 = p0; q0 < p1; q0 += kChunk) {
    const int64_t count = std::min(kChunk, p1 - q0);
    chunk_taps<false>(gp, g, n, q0, count, p, t);
    for (int64_t c = c0; c < c1; ++c) {
      float* plane = gx_n + c * g.h * g.w;
      const float* go = gyp + (n * g.c + c) * g.points + q0;
      for (int64_t i = 0; i < count; ++i) {
        const float v = go[i];
        plane[t.off[0][i]] += t.w[0][i] * v;
        plane[t.off[1][i]] += t.w[1][i] * v;
        plane[t.off[2][i]] += t.w[2][i] * v;
        plane[t.off[3][i]] += t.w[3][i] * v;
      }
    }
  }
}

void grid_sample_grad_input(const float* gyp, const float* gp, float* gxp, const GridGeometry& g,
                            const GridSampleParams& p) {
  const int64_t plane_size = g.h * g.w, planes = g.n * g.c;
  if (planes == 0) return;
  const int threads = max_threads();
  if (planes >= threads || planes * g.points * 8 < kParallelGrain) {
    // Tasks own (image, block of channels): blocks only as fine as needed to fill the threads.
    const int64_t blocks = std::clamp<int64_t>((2 * threads + g.n - 1) / g.n, 1, g.c);
    const int64_t block_c = (g.c + blocks - 1) / blocks;
    parallel_ranges(g.n * blocks, g.points * (block_c * 8 + 30), [&](int64_t b, int64_t e) {
      auto taps = std::make_unique<ChunkTaps>();
      for (int64_t task = b; task < e; ++task) {
        const int64_t n = task / blocks, c0 = (task % blocks) * block_c;
        const int64_t c1 = std::min(g.c, c0 + block_c);
        if (c0 >= c1) continue;
        float* gx_n = gxp + n * g.c * plane_size;
        std::fill(gx_n + c0 * plane_size, gx_n + c1 * plane_size, 0.0f);
        scatter_points(gyp, gp, gx_n, g, p, n, c0, c1, 0, g.points, *taps);
      }
    });
    return;
  }
  // Few planes: threads split the points and scatter into private copies of gx.
  const int64_t total = planes * plane_size;
  std::vector<float> priv(static_cast<size_t>(threads * total), 0.0f);
  const int used = parallel_ranges_indexed(
      g.n * g.points, g.c * 8 + 30, threads, [&](int t, int64_t b, int64_t e) {
        auto taps = std::make_unique<ChunkTaps>();
        float* mine = priv.data() + t * total;
        for (int64_t q = b; q < e;) {  // split [b, e) at image boundaries
          const int64_t n = q / g.points, p0 = q % g.points;
          const int64_t p1 = std::min(g.points, p0 + (e - q));
          scatter_points(gyp, gp, mine + n * g.c * plane_size, g, p, n, 0, g.c, p0, p1, *taps);
          q += p1 - p0;
        }
      });
  parallel_ranges(total, used, [&](int64_t b, int64_t e) {
    for (int64_t i = b; i < e; ++i) {
      float s = 0.0f;
      for (int t = 0; t < used; ++t) s += priv[t * total + i];
      gxp[i] = s;
    }
  });
}

// in {gy [N,C,OH,OW], x [N,C,H,W], grid [N,OH,OW,2]}, out {gx?, ggrid?}; GridSampleParams.
void grid_sample_backward(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 3 && a.out.size() == 2 && a.params != nullptr);
  const Tensor& gy = a.in[0];
  const Tensor& x = a.in[1];
  const Tensor& grid = a.in[2];
  const Tensor& gx = a.out[0];
  const Tensor& ggrid = a.out[1];
  const GridSampleParams& p = a.p<GridSampleParams>();
  const GridGeometry g = grid_geometry(x, grid, gy);
  const float* gp = grid.data<float>();
  if (ggrid.defined()) {
    CVD_ASSERT(ggrid.dtype() == DType::f32 && ggrid.is_contiguous());
    CVD_ASSERT(ggrid.shape() == grid.shape());
    grid_sample_grad_grid(gy.data<float>(), x.data<float>(), gp, ggrid.data<float>(), g, p);
  }
  if (gx.defined()) {
    CVD_ASSERT(gx.dtype() == DType::f32 && gx.is_contiguous() && gx.shape() == x.shape());
    grid_sample_grad_input(gy.data<float>(), gp, gx.data<float>(), g, p);
  }
}

}  // namespace

void register_grid_sample_kernels(KernelRegistry& r) {
  r.add(OpId::grid_sample, DeviceType::cpu, DType::f32, grid_sample, "openmp");
  r.add(OpId::grid_sample_backward, DeviceType::cpu, DType::f32, grid_sample_backward, "openmp");
}

}  // namespace cvd::cpu
