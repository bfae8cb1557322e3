// OpenMP f32 kernels of FlowNet's correlation and ChannelNorm (semantics in
// engine/kernel_params.h, CorrelationParams), forward and backward.
//   correlation forward: parallel over output rows (image, oy); for each displacement the row is
//     accumulated in a local buffer over channels and kernel offsets as row-times-row products
//     (contiguous in x when stride1 == 1, so the inner loop vectorises), with the range of
//     output columns whose two reads lie inside the image computed once per (offset,
//     displacement) instead of testing every element.
//   correlation backward: parallel over (image, block of channels); a task walks every output
//     and scatters into its own channel planes of ga and gb only, so no atomics are needed.
//   channel_norm (+ backward): parallel over pixels.
#include <algorithm>
#include <cmath>
#include <vector>

#include "engine/dispatch.h"
#include "engine/kernel_params.h"
#include "kernels/cpu/cpu_parallel.h"

namespace cvd::cpu {

namespace {

struct CorrelationGeometry {
  int64_t n, c, h, w, oh, ow;
  int r, d, kr, s1, s2;
  int64_t offset;  // image coordinate of output index 0's patch centre: border - pad
  float scale;     // 1 / (k^2 C)
};

CorrelationGeometry correlation_geometry(const Tensor& a, const Tensor& b, const Tensor& y,
                                         const CorrelationParams& p) {
  for (const Tensor* t : {&a, &b, &y}) {
    CVD_ASSERT(t->defined() && t->device().is_cpu() && t->dtype() == DType::f32);
    CVD_ASSERT(t->is_contiguous() && t->dim() == 4);
  }
  CVD_ASSERT(a.shape() == b.shape() && y.shape()[0] == a.shape()[0]);
  CVD_ASSERT(y.shape()[1] == int64_t{p.displacement_size()} * p.displacement_size());
  CVD_ASSERT(y.shape()[2] == p.out_size(a.shape()[2]) && y.shape()[3] == p.out_size(a.shape()[3]));
  CorrelationGeometry g;
  g.n = a.shape()[0];
  g.c = a.shape()[1];
  g.h = a.shape()[2];
  g.w = a.shape()[3];
  g.oh = y.shape()[2];
  g.ow = y.shape()[3];
  g.r = p.displacement_radius();
  g.d = p.displacement_size();
  g.kr = p.kernel_radius();
  g.s1 = p.stride1;
  g.s2 = p.stride2;
  g.offset = p.border() - p.pad;
  g.scale = 1.0f / (static_cast<float>(p.kernel_size) * p.kernel_size * static_cast<float>(g.c));
  return g;
}

// Output columns [lo, hi) whose reads x_a = ox * s1 + base and x_a + shift both lie in [0, w).
struct ColumnRange {
  int64_t lo, hi;
};

ColumnRange valid_columns(int64_t base, int64_t shift, int64_t s1, int64_t w, int64_t ow) {
  // Need 0 <= ox * s1 + base + e < w for e in {0, shift}.
  const int64_t lo_bound = -std::min<int64_t>(0, shift) - base;         // ox * s1 >= lo_bound
  const int64_t hi_bound = w - std::max<int64_t>(0, shift) - base - 1;  // ox * s1 <= hi_bound
  auto ceil_div = [](int64_t a, int64_t b) { return a >= 0 ? (a + b - 1) / b : -((-a) / b); };
  auto floor_div = [](int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); };
  const int64_t lo = std::max<int64_t>(0, ceil_div(lo_bound, s1));
  const int64_t hi = std::min<int64_t>(ow, floor_div(hi_bound, s1) + 1);
  return {lo, std::max(lo, hi)};
}

void correlation_forward(const KernelArgs& args) {
  const Tensor &a = args.in[0], &b = args.in[1], &y = args.out[0];
  const CorrelationGeometry g = correlation_geometry(a, b, y, args.p<CorrelationParams>());
  const float* ap = a.data<float>();
  const float* bp = b.data<float>();
  float* yp = y.data<float>();
  const int64_t plane = g.h * g.w, oplane = g.oh * g.ow;
  const int64_t k = 2 * g.kr + 1;
  const int64_t cost = int64_t{g.d} * g.d * g.c * k * k * g.ow;
  parallel_ranges(g.n * g.oh, cost, [&](int64_t begin, int64_t end) {
    std::vector<float> acc(static_cast<size_t>(g.ow));
    for (int64_t task = begin; task < end; ++task) {
      const int64_t n = task / g.oh, oy = task % g.oh;
      const int64_t cy = oy * g.s1 + g.offset;
      const float* a_img = ap + n * g.c * plane;
      const float* b_img = bp + n * g.c * plane;
      for (int tj = -g.r; tj <= g.r; ++tj) {
        for (int ti = -g.r; ti <= g.r; ++ti) {
          std::fill(acc.begin(), acc.end(), 0.0f);
          const int64_t shift_x = int64_t{ti} * g.s2;
          for (int dj = -g.kr; dj <= g.kr; ++dj) {
            const int64_t ya = cy + dj, yb = ya + int64_t{tj} * g.s2;
            if (ya < 0 || ya >= g.h || yb < 0 || yb >= g.h) continue;
            for (int di = -g.kr; di <= g.kr; ++di) {
              const int64_t base = g.offset + di;
              const ColumnRange cols = valid_columns(base, shift_x, g.s1, g.w, g.ow);
              if (cols.lo >= cols.hi) continue;
              // Pointers at the first valid column (x_a = lo * s1 + base >= 0).
              const int64_t xa0 = cols.lo * g.s1 + base, len = cols.hi - cols.lo;
              float* out = acc.data() + cols.lo;
              for (int64_t c = 0; c < g.c; ++c) {
                const float* arow = a_img + c * plane + ya * g.w + xa0;
                const float* brow = b_img + c * plane + yb * g.w + xa0 + shift_x;
                if (g.s1 == 1) {
#pragma omp simd
                  for (int64_t i = 0; i < len; ++i) out[i] += arow[i] * brow[i];
                } else {
                  for (int64_t i = 0; i < len; ++i) out[i] += arow[i * g.s1] * brow[i * g.s1];
                }
              }
            }
          }
          const int64_t oc = int64_t{tj + g.r} * g.d + (ti + g.r);
          float* yrow = yp + (n * g.d * g.d + oc) * oplane + oy * g.ow;
          for (int64_t ox = 0; ox < g.ow; ++ox) yrow[ox] = acc[static_cast<size_t>(ox)] * g.scale;
        }
      }
    }
  });
}

constexpr int64_t kChannelBlock = 8;

// in: gy, a, b; out: ga, gb (either may be undefined).
void correlation_backward(const KernelArgs& args) {
  const Tensor &gy = args.in[0], &a = args.in[1], &b = args.in[2];
  const Tensor &ga = args.out[0], &gb = args.out[1];
  const CorrelationGeometry g = correlation_geometry(a, b, gy, args.p<CorrelationParams>());
  for (const Tensor* t : {&ga, &gb}) {
    if (!t->defined()) continue;
    CVD_ASSERT(t->dtype() == DType::f32 && t->is_contiguous() && t->shape() == a.shape());
    std::fill_n(t->data<float>(), t->numel(), 0.0f);
  }
  const float* ap = a.data<float>();
  const float* bp = b.data<float>();
  const float* gp = gy.data<float>();
  float* gap = ga.defined() ? ga.data<float>() : nullptr;
  float* gbp = gb.defined() ? gb.data<float>() : nullptr;
  const int64_t plane = g.h * g.w, oplane = g.oh * g.ow;
  const int64_t blocks = (g.c + kChannelBlock - 1) / kChannelBlock;
  const int64_t k = 2 * g.kr + 1;
  const int64_t cost = int64_t{g.d} * g.d * kChannelBlock * k * k * oplane * 2;
  parallel_ranges(g.n * blocks, cost, [&](int64_t begin, int64_t end) {
    std::vector<float> grow(static_cast<size_t>(g.ow));
    for (int64_t task = begin; task < end; ++task) {
      const int64_t n = task / blocks, c0 = (task % blocks) * kChannelBlock;
      const int64_t c1 = std::min(g.c, c0 + kChannelBlock);
      for (int64_t oy = 0; oy < g.oh; ++oy) {
        const int64_t cy = oy * g.s1 + g.offset;
        for (int tj = -g.r; tj <= g.r; ++tj) {
          for (int ti = -g.r; ti <= g.r; ++ti) {
            const int64_t oc = int64_t{tj + g.r} * g.d + (ti + g.r);
            const float* gsrc = gp + (n * g.d * g.d + oc) * oplane + oy * g.ow;
            for (int64_t ox = 0; ox < g.ow; ++ox)
              grow[static_cast<size_t>(ox)] = gsrc[ox] * g.scale;
            const int64_t shift_x = int64_t{ti} * g.s2;
            for (int dj = -g.kr; dj <= g.kr; ++dj) {
              const int64_t ya = cy + dj, yb = ya + int64_t{tj} * g.s2;
              if (ya < 0 || ya >= g.h || yb < 0 || yb >= g.h) continue;
              for (int di = -g.kr; di <= g.kr; ++di) {
                const int64_t base = g.offset + di;
                const ColumnRange cols = valid_columns(base, shift_x, g.s1, g.w, g.ow);
                if (cols.lo >= cols.hi) continue;
                const int64_t xa0 = cols.lo * g.s1 + base, len = cols.hi - cols.lo;
                const int64_t s = g.s1;
                const float* gr = grow.data() + cols.lo;
                for (int64_t c = c0; c < c1; ++c) {
                  const int64_t ia = (n * g.c + c) * plane + ya * g.w + xa0;
                  const int64_t ib = (n * g.c + c) * plane + yb * g.w + xa0 + shift_x;
                  if (gap) {
                    float* out = gap + ia;
                    const float* in = bp + ib;
                    for (int64_t i = 0; i < len; ++i) out[i * s] += gr[i] * in[i * s];
                  }
                  if (gbp) {
                    float* out = gbp + ib;
                    const float* in = ap + ia;
                    for (int64_t i = 0; i < len; ++i) out[i * s] += gr[i] * in[i * s];
                  }
                }
              }
            }
          }
        }
      }
    }
  });
}

struct NormGeometry {
  int64_t n, c, hw;
};

NormGeometry norm_geometry(const Tensor& x, const Tensor& y) {
  for (const Tensor* t : {&x, &y}) {
    CVD_ASSERT(t->defined() && t->device().is_cpu() && t->dtype() == DType::f32);
    CVD_ASSERT(t->is_contiguous() && t->dim() == 4);
  }
  const int64_t hw = x.shape()[2] * x.shape()[3];
  CVD_ASSERT(y.shape()[0] == x.shape()[0] && y.shape()[1] == 1 &&
             y.shape()[2] * y.shape()[3] == hw);
  return {x.shape()[0], x.shape()[1], hw};
}

void channel_norm(const KernelArgs& args) {
  const Tensor &x = args.in[0], &y = args.out[0];
  const NormGeometry g = norm_geometry(x, y);
  const float* xp = x.data<float>();
  float* yp = y.data<float>();
  parallel_ranges(g.n * g.hw, g.c, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) {
      const int64_t n = i / g.hw, p = i % g.hw;
      const float* src = xp + n * g.c * g.hw + p;
      float s = 0.0f;
      for (int64_t c = 0; c < g.c; ++c) s += src[c * g.hw] * src[c * g.hw];
      yp[i] = std::sqrt(s);
    }
  });
}

// in: gy, x, y; out: gx = gy * x / y, 0 where y == 0.
void channel_norm_backward(const KernelArgs& args) {
  const Tensor &gy = args.in[0], &x = args.in[1], &y = args.in[2], &gx = args.out[0];
  const NormGeometry g = norm_geometry(x, y);
  CVD_ASSERT(gy.is_contiguous() && gy.shape() == y.shape() && gy.dtype() == DType::f32);
  CVD_ASSERT(gx.is_contiguous() && gx.shape() == x.shape() && gx.dtype() == DType::f32);
  const float* gyp = gy.data<float>();
  const float* xp = x.data<float>();
  const float* yp = y.data<float>();
  float* gxp = gx.data<float>();
  parallel_ranges(g.n * g.hw, g.c, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) {
      const int64_t n = i / g.hw, p = i % g.hw;
      const float f = yp[i] > 0.0f ? gyp[i] / yp[i] : 0.0f;
      const float* src = xp + n * g.c * g.hw + p;
      float* dst = gxp + n * g.c * g.hw + p;
      for (int64_t c = 0; c < g.c; ++c) dst[c * g.hw] = f * src[c * g.hw];
    }
  });
}

}  // namespace

void register_correlation_kernels(KernelRegistry& r) {
  r.add(OpId::correlation, DeviceType::cpu, DType::f32, correlation_forward, "openmp");
  r.add(OpId::correlation_backward, DeviceType::cpu, DType::f32, correlation_backward, "openmp");
  r.add(OpId::channel_norm, DeviceType::cpu, DType::f32, channel_norm, "openmp");
  r.add(OpId::channel_norm_backward, DeviceType::cpu, DType::f32, channel_norm_backward, "openmp");
}

}  // namespace cvd::cpu
