// OpenMP f32 kernels of the 2-D resizes (PyTorch semantics, any output size): bilinear (both
// align_corners modes), bicubic and nearest, forward and backward. The per-axis taps come from the shared
// engine/resample_math.h and are computed once per call; bilinear source coordinates are
// computed in double (free, and it keeps large resizes within f32 rounding of the exact result,
// where a float coordinate of ~150 px is already off by ~1e-5 px).
// Forward: parallel over output rows of all planes.
// Backward, race-free without atomics: parallel over input rows of all planes; each task gathers
// the output rows whose taps land on its input row (taps are monotonic in the output index, so
// those output rows are contiguous) and writes only its own row.
#include <algorithm>
#include <cstring>
#include <vector>

#include "engine/resample_math.h"
#include "kernels/cpu/cpu_openmp_families.h"
#include "kernels/cpu/cpu_parallel.h"

namespace cvd::cpu {

namespace {

// Taps of every output index along one axis.
struct AxisTaps {
  std::vector<int64_t> i0, i1;
  std::vector<float> w0, w1;
};

AxisTaps linear_axis_taps(int64_t in, int64_t out, bool align_corners) {
  AxisTaps t;
  t.i0.resize(out), t.i1.resize(out), t.w0.resize(out), t.w1.resize(out);
  for (int64_t o = 0; o < out; ++o) {
    const LinearResizeTaps<double> k = resize_linear_taps<double>(o, in, out, align_corners);
    t.i0[o] = k.i0, t.i1[o] = k.i1;
    t.w0[o] = static_cast<float>(k.w0), t.w1[o] = static_cast<float>(k.w1);
  }
  return t;
}

std::vector<int64_t> nearest_axis_index(int64_t in, int64_t out) {
  std::vector<int64_t> idx(static_cast<size_t>(out));
  for (int64_t o = 0; o < out; ++o) idx[o] = nearest_source_index(o, in, out);
  return idx;
}

struct ResizeGeometry {
  int64_t planes, h, w, oh, ow;
};

// x [N, C, H, W] (the small side in backward: gx) and y [N, C, OH, OW].
ResizeGeometry resize_geometry(const Tensor& x, const Tensor& y) {
  for (const Tensor* t : {&x, &y}) {
    CVD_ASSERT(t->defined() && t->device().is_cpu() && t->dtype() == DType::f32);
    CVD_ASSERT(t->is_contiguous() && t->dim() == 4);
  }
  CVD_ASSERT(x.shape()[0] == y.shape()[0] && x.shape()[1] == y.shape()[1]);
  CVD_ASSERT(x.shape()[2] >= 1 && x.shape()[3] >= 1);
  return {x.shape()[0] * x.shape()[1], x.shape()[2], x.shape()[3], y.shape()[2], y.shape()[3]};
}

// out[c] = w0[c] * row[i0[c]] + w1[c] * row[i1[c]]: one row interpolated along x.
void interpolate_row(const float* row, const AxisTaps& tw, int64_t ow, float* out) {
  const int64_t* c0 = tw.i0.data();
  const int64_t* c1 = tw.i1.data();
  const float* w0 = tw.w0.data();
  const float* w1 = tw.w1.data();
  for (int64_t c = 0; c < ow; ++c) out[c] = w0[c] * row[c0[c]] + w1[c] * row[c1[c]];
}

// in {x [N,C,H,W]}, out {y [N,C,OH,OW]}; UpsampleParams.
// Separable: input rows are interpolated along x once into a two-row cache, then blended along
// y (PyTorch's h0 * (w0 a + w1 b) + h1 * (w0 c + w1 d), in the same order).
void upsample_bilinear2d(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1 && a.params != nullptr);
  const Tensor& x = a.in[0];
  const Tensor& y = a.out[0];
  const ResizeGeometry g = resize_geometry(x, y);
  const bool ac = a.p<UpsampleParams>().align_corners;
  const AxisTaps th = linear_axis_taps(g.h, g.oh, ac), tw = linear_axis_taps(g.w, g.ow, ac);
  const float* xp = x.data<float>();
  float* yp = y.data<float>();
  parallel_ranges(g.planes * g.oh, g.ow * 4, [&](int64_t b, int64_t e) {
    std::vector<float> cache(static_cast<size_t>(2 * g.ow));
    int64_t cached[2] = {-1, -1};  // plane * H + input row held by each cache slot
    // The cache slot holding input row `key`, interpolating it along x when absent; `keep` is
    // the slot that must not be evicted.
    auto row_slot = [&](int64_t key, int keep) -> const float* {
      for (int s = 0; s < 2; ++s) {
        if (cached[s] == key) return cache.data() + s * g.ow;
      }
      const int s = keep == 0 ? 1 : 0;
      cached[s] = key;
      interpolate_row(xp + key * g.w, tw, g.ow, cache.data() + s * g.ow);
      return cache.data() + s * g.ow;
    };
    for (int64_t t = b; t < e; ++t) {
      const int64_t plane = t / g.oh, r = t % g.oh;
      const float* r0 = row_slot(plane * g.h + th.i0[r], -1);
      const int keep = r0 == cache.data() ? 0 : 1;
      const float* r1 = row_slot(plane * g.h + th.i1[r], keep);
      const float h0 = th.w0[r], h1 = th.w1[r];
      float* out = yp + t * g.ow;
      for (int64_t c = 0; c < g.ow; ++c) out[c] = h0 * r0[c] + h1 * r1[c];
    }
  });
}

// in {gy [N,C,OH,OW]}, out {gx [N,C,H,W]}; UpsampleParams.
// Separable and race-free: each task owns input rows; for row h it sums, along y, the output
// rows whose taps include h (contiguous ranges, as taps are monotonic), then scatters that sum
// along x into its own row.
void upsample_bilinear2d_backward(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1 && a.params != nullptr);
  const Tensor& gy = a.in[0];
  const Tensor& gx = a.out[0];
  const ResizeGeometry g = resize_geometry(gx, gy);
  const bool ac = a.p<UpsampleParams>().align_corners;
  const AxisTaps th = linear_axis_taps(g.h, g.oh, ac), tw = linear_axis_taps(g.w, g.ow, ac);
  const float* gyp = gy.data<float>();
  float* gxp = gx.data<float>();
  const int64_t per_row = (2 * g.oh * g.ow) / g.h + 2 * g.ow + g.w;
  parallel_ranges(g.planes * g.h, per_row, [&](int64_t b, int64_t e) {
    std::vector<float> acc(static_cast<size_t>(g.ow));
    float* sum = acc.data();
    for (int64_t t = b; t < e; ++t) {
      const int64_t plane = t / g.h, h = t % g.h;
      std::fill(acc.begin(), acc.end(), 0.0f);
      for (int tap = 0; tap < 2; ++tap) {
        const std::vector<int64_t>& rows = tap == 0 ? th.i0 : th.i1;
        const std::vector<float>& weights = tap == 0 ? th.w0 : th.w1;
        const auto range = std::equal_range(rows.begin(), rows.end(), h);
        for (auto it = range.first; it != range.second; ++it) {
          const int64_t r = it - rows.begin();
          const float wr = weights[r];
          const float* src = gyp + (plane * g.oh + r) * g.ow;
          for (int64_t c = 0; c < g.ow; ++c) sum[c] += wr * src[c];
        }
      }
      float* dst = gxp + t * g.w;
      std::fill(dst, dst + g.w, 0.0f);
      for (int64_t c = 0; c < g.ow; ++c) {
        dst[tw.i0[c]] += tw.w0[c] * sum[c];
        dst[tw.i1[c]] += tw.w1[c] * sum[c];
      }
    }
  });
}

// in {x [N,C,H,W]}, out {y [N,C,OH,OW]}.
void upsample_nearest2d(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1);
  const Tensor& x = a.in[0];
  const Tensor& y = a.out[0];
  const ResizeGeometry g = resize_geometry(x, y);
  const std::vector<int64_t> rows = nearest_axis_index(g.h, g.oh);
  const std::vector<int64_t> cols = nearest_axis_index(g.w, g.ow);
  const float* xp = x.data<float>();
  float* yp = y.data<float>();
  const int64_t* ci = cols.data();
  parallel_ranges(g.planes * g.oh, g.ow, [&](int64_t b, int64_t e) {
    for (int64_t t = b; t < e; ++t) {
      const int64_t plane = t / g.oh, r = t % g.oh;
      float* out = yp + t * g.ow;
      if (t > b && r > 0 && rows[r] == rows[r - 1]) {  // same source row as the row above
        std::memcpy(out, out - g.ow, static_cast<size_t>(g.ow) * sizeof(float));
        continue;
      }
      const float* src = xp + (plane * g.h + rows[r]) * g.w;
      for (int64_t c = 0; c < g.ow; ++c) out[c] = src[ci[c]];
    }
  });
}

// in {gy [N,C,OH,OW]}, out {gx [N,C,H,W]}: every input row gathers the output rows mapped to it.
void upsample_nearest2d_backward(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1);
  const Tensor& gy = a.in[0];
  const Tensor& gx = a.out[0];
  const ResizeGeometry g = resize_geometry(gx, gy);
  const std::vector<int64_t> rows = nearest_axis_index(g.h, g.oh);
  const std::vector<int64_t> cols = nearest_axis_index(g.w, g.ow);
  const float* gyp = gy.data<float>();
  float* gxp = gx.data<float>();
  const int64_t* ci = cols.data();
  const int64_t per_row = (g.oh * g.ow) / g.h + g.w;
  parallel_ranges(g.planes * g.h, per_row, [&](int64_t b, int64_t e) {
    for (int64_t t = b; t < e; ++t) {
      const int64_t plane = t / g.h, h = t % g.h;
      float* dst = gxp + t * g.w;
      std::fill(dst, dst + g.w, 0.0f);
      // rows is non-decreasing: the output rows mapped to h are contiguous.
      const auto range = std::equal_range(rows.begin(), rows.end(), h);
      for (auto it = range.first; it != range.second; ++it) {
        const float* src = gyp + (plane * g.oh + (it - rows.begin())) * g.ow;
        for (int64_t c = 0; c < g.ow; ++c) dst[ci[c]] += src[c];
      }
    }
  });
}

// Bicubic taps of every output index along one axis (weights in double: the 16 products per
// output are then formed in double and rounded once).
std::vector<CubicResizeTaps<double>> cubic_axis_taps(int64_t in, int64_t out, bool align_corners,
                                                     double scale) {
  std::vector<CubicResizeTaps<double>> t(static_cast<size_t>(out));
  for (int64_t o = 0; o < out; ++o)
    t[o] = resize_cubic_taps<double>(o, in, out, align_corners, scale);
  return t;
}

// in {x [N,C,H,W]}, out {y [N,C,OH,OW]}; UpsampleParams. Parallel over output rows of all planes.
void upsample_bicubic2d(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1 && a.params != nullptr);
  const ResizeGeometry g = resize_geometry(a.in[0], a.out[0]);
  const UpsampleParams& p = a.p<UpsampleParams>();
  const auto th = cubic_axis_taps(g.h, g.oh, p.align_corners, p.scale_h);
  const auto tw = cubic_axis_taps(g.w, g.ow, p.align_corners, p.scale_w);
  const float* xp = a.in[0].data<float>();
  float* yp = a.out[0].data<float>();
  parallel_ranges(g.planes * g.oh, g.ow * 16, [&](int64_t b, int64_t e) {
    for (int64_t t = b; t < e; ++t) {
      const int64_t plane = t / g.oh, r = t % g.oh;
      const float* x = xp + plane * g.h * g.w;
      for (int64_t c = 0; c < g.ow; ++c) {
        double acc = 0.0;
        for (int i = 0; i < 4; ++i) {
          const float* row = x + th[r].i[i] * g.w;
          double s = 0.0;
          for (int j = 0; j < 4; ++j) s += tw[c].w[j] * row[tw[c].i[j]];
          acc += th[r].w[i] * s;
        }
        yp[t * g.ow + c] = static_cast<float>(acc);
      }
    }
  });
}

// in {gy [N,C,OH,OW]}, out {gx [N,C,H,W]}; UpsampleParams. Race-free: each task owns whole
// planes and scatters into them.
void upsample_bicubic2d_backward(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1 && a.params != nullptr);
  const ResizeGeometry g = resize_geometry(a.out[0], a.in[0]);
  const UpsampleParams& p = a.p<UpsampleParams>();
  const auto th = cubic_axis_taps(g.h, g.oh, p.align_corners, p.scale_h);
  const auto tw = cubic_axis_taps(g.w, g.ow, p.align_corners, p.scale_w);
  const float* gyp = a.in[0].data<float>();
  float* gxp = a.out[0].data<float>();
  parallel_ranges(g.planes, g.oh * g.ow * 16 + g.h * g.w, [&](int64_t b, int64_t e) {
    std::vector<double> acc(static_cast<size_t>(g.h * g.w));
    for (int64_t plane = b; plane < e; ++plane) {
      std::fill(acc.begin(), acc.end(), 0.0);
      const float* gy = gyp + plane * g.oh * g.ow;
      for (int64_t r = 0; r < g.oh; ++r)
        for (int64_t c = 0; c < g.ow; ++c) {
          const double v = gy[r * g.ow + c];
          for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j)
              acc[th[r].i[i] * g.w + tw[c].i[j]] += th[r].w[i] * tw[c].w[j] * v;
        }
      float* gx = gxp + plane * g.h * g.w;
      for (int64_t k = 0; k < g.h * g.w; ++k) gx[k] = static_cast<float>(acc[k]);
    }
  });
}

}  // namespace

void register_resize_kernels(KernelRegistry& r) {
  r.add(OpId::upsample_bicubic2d, DeviceType::cpu, DType::f32, upsample_bicubic2d, "openmp");
  r.add(OpId::upsample_bicubic2d_backward, DeviceType::cpu, DType::f32, upsample_bicubic2d_backward,
        "openmp");
  r.add(OpId::upsample_bilinear2d, DeviceType::cpu, DType::f32, upsample_bilinear2d, "openmp");
  r.add(OpId::upsample_bilinear2d_backward, DeviceType::cpu, DType::f32,
        upsample_bilinear2d_backward, "openmp");
  r.add(OpId::upsample_nearest2d, DeviceType::cpu, DType::f32, upsample_nearest2d, "openmp");
  r.add(OpId::upsample_nearest2d_backward, DeviceType::cpu, DType::f32, upsample_nearest2d_backward,
        "openmp");
}

}  // namespace cvd::cpu
