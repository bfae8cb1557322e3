// CUDA kernel bodies and op drivers of FlowNetC correlation and ChannelNorm, forward and backward
// (semantics in engine/kernel_params.h, CorrelationParams). The correlation forward is a gather
// (one thread per output element); its backward runs one thread per output element too and
// scatters into ga / gb with atomic_add (zeroed first).
#pragma once
#include <cmath>

#include "engine/dispatch.h"
#include "engine/kernel_params.h"
#include "kernels/cuda/launch_body.h"
#include "kernels/cuda/resample_body.h"

namespace cvd::cuda {

struct CorrelationGeometry {
  int64_t n, c, h, w, oc, oh, ow;
  int r, d, kr, border, pad, stride1, stride2;
  float scale;  // 1 / (k^2 C)
};

inline CorrelationGeometry correlation_geometry(const Tensor& a, const Tensor& y,
                                                const CorrelationParams& p) {
  return {a.shape()[0],
          a.shape()[1],
          a.shape()[2],
          a.shape()[3],
          y.shape()[1],
          y.shape()[2],
          y.shape()[3],
          p.displacement_radius(),
          p.displacement_size(),
          p.kernel_radius(),
          p.border(),
          p.pad,
          p.stride1,
          p.stride2,
          static_cast<float>(1.0 / (static_cast<double>(p.kernel_size) * p.kernel_size *
                                    static_cast<double>(a.shape()[1])))};
}

// Calls f(ia, ib) for every product a[ia] * b[ib] of output element io (flat offsets).
template <class F>
CVD_HOST_DEVICE void for_each_correlation_product(const CorrelationGeometry& g, int64_t io,
                                                  const F& f) {
  const int64_t ox = io % g.ow, oy = (io / g.ow) % g.oh, oc = (io / (g.ow * g.oh)) % g.oc;
  const int64_t n = io / (g.ow * g.oh * g.oc);
  const int64_t tj = oc / g.d - g.r, ti = oc % g.d - g.r;
  const int64_t cy = oy * g.stride1 + g.border - g.pad, cx = ox * g.stride1 + g.border - g.pad;
  for (int dj = -g.kr; dj <= g.kr; ++dj)
    for (int di = -g.kr; di <= g.kr; ++di) {
      const int64_t ya = cy + dj, xa = cx + di;
      const int64_t yb = ya + tj * g.stride2, xb = xa + ti * g.stride2;
      if (ya < 0 || ya >= g.h || xa < 0 || xa >= g.w) continue;
      if (yb < 0 || yb >= g.h || xb < 0 || xb >= g.w) continue;
      for (int64_t c = 0; c < g.c; ++c) {
        const int64_t plane = (n * g.c + c) * g.h;
        f((plane + ya) * g.w + xa, (plane + yb) * g.w + xb);
      }
    }
}

template <class T>
struct CorrelationBody {
  const T *a, *b;
  T* y;
  CorrelationGeometry g;
  CVD_HOST_DEVICE void operator()(int64_t io) const {
    T acc = T(0);
    const T *ap = a, *bp = b;
    for_each_correlation_product(g, io, [&](int64_t ia, int64_t ib) { acc += ap[ia] * bp[ib]; });
    y[io] = acc * static_cast<T>(g.scale);
  }
};

template <class T>
struct CorrelationBackwardBody {
  const T *gy, *a, *b;
  T *ga, *gb;  // either may be nullptr
  CorrelationGeometry g;
  CVD_HOST_DEVICE void operator()(int64_t io) const {
    const T s = gy[io] * static_cast<T>(g.scale);
    if (s == T(0)) return;
    const T *ap = a, *bp = b;
    T *gap = ga, *gbp = gb;
    for_each_correlation_product(g, io, [&](int64_t ia, int64_t ib) {
      if (gap) atomic_add(gap + ia, s * bp[ib]);
      if (gbp) atomic_add(gbp + ib, s * ap[ia]);
    });
  }
};

// y[n, 0, p] = sqrt(sum_c x[n, c, p]^2); one thread per (n, p).
template <class T>
struct ChannelNormBody {
  const T* x;
  T* y;
  int64_t c, hw;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    const int64_t n = i / hw, p = i % hw;
    T s = T(0);
    for (int64_t ch = 0; ch < c; ++ch) {
      const T v = x[(n * c + ch) * hw + p];
      s += v * v;
    }
    y[i] = sqrt(s);
  }
};

// gx = gy * x / y (0 where y == 0); one thread per element of x.
template <class T>
struct ChannelNormBackwardBody {
  const T *gy, *x, *y;
  T* gx;
  int64_t c, hw;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    const int64_t p = i % hw, n = i / (c * hw);
    const T norm = y[n * hw + p];
    gx[i] = norm > T(0) ? gy[n * hw + p] / norm * x[i] : T(0);
  }
};

// ---- Op drivers ---------------------------------------------------------------------------------

template <class Launch>
void correlation_op(const KernelArgs& args) {
  const Tensor &a = args.in[0], &b = args.in[1], &y = args.out[0];
  Launch::launch(y.numel(),
                 CorrelationBody<float>{a.data<float>(), b.data<float>(), y.data<float>(),
                                        correlation_geometry(a, y, args.p<CorrelationParams>())});
}

template <class Launch>
void correlation_backward_op(const KernelArgs& args) {
  const Tensor &gy = args.in[0], &a = args.in[1], &b = args.in[2];
  float* ga = data_or_null<float>(args.out[0]);
  float* gb = args.out.size() > 1 ? data_or_null<float>(args.out[1]) : nullptr;
  if (ga) Launch::launch(a.numel(), ZeroBody<float>{ga});
  if (gb) Launch::launch(b.numel(), ZeroBody<float>{gb});
  Launch::launch(gy.numel(), CorrelationBackwardBody<float>{
                                 gy.data<float>(), a.data<float>(), b.data<float>(), ga, gb,
                                 correlation_geometry(a, gy, args.p<CorrelationParams>())});
}

template <class Launch>
void channel_norm_op(const KernelArgs& args) {
  const Tensor &x = args.in[0], &y = args.out[0];
  Launch::launch(y.numel(), ChannelNormBody<float>{x.data<float>(), y.data<float>(), x.shape()[1],
                                                   x.shape()[2] * x.shape()[3]});
}

template <class Launch>
void channel_norm_backward_op(const KernelArgs& args) {
  const Tensor &gy = args.in[0], &x = args.in[1], &y = args.in[2], &gx = args.out[0];
  Launch::launch(gx.numel(), ChannelNormBackwardBody<float>{
                                 gy.data<float>(), x.data<float>(), y.data<float>(),
                                 gx.data<float>(), x.shape()[1], x.shape()[2] * x.shape()[3]});
}

}  // namespace cvd::cuda
