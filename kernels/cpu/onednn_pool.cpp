// max_pool2d, avg_pool2d and avg_pool2d_backward on oneDNN pooling primitives (NCHW), with
// PyTorch semantics; hand-written with OpenMP where oneDNN differs:
// - max_pool2d_backward: oneDNN needs the forward's workspace, which is not kept between calls;
//   the hand-written pass recomputes each window's argmax (PyTorch rule: the first maximum in
//   row-major window order, a NaN wins).
// - average pooling with count_include_pad in ceil mode when a window runs past the right
//   padding: PyTorch divides by the window clipped to the padded input, oneDNN by the kernel
//   size;
// - any forward geometry oneDNN declines to build a primitive for.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "engine/error.h"
#include "engine/kernel_params.h"
#include "kernels/cpu/cpu_parallel.h"
#include "kernels/cpu/onednn_context.h"
#include "kernels/cpu/onednn_kernels.h"

namespace cvd::onednn {

namespace {

using tag = dnnl::memory::format_tag;

// Pooling of planes [N*C] of h x w into oh x ow.
struct PoolGeometry {
  int64_t n, c, h, w, oh, ow;
  int64_t planes() const { return n * c; }
};

PoolGeometry geometry(const Tensor& x, const Tensor& y) {
  return {x.shape()[0], x.shape()[1], x.shape()[2], x.shape()[3], y.shape()[2], y.shape()[3]};
}

// The right / bottom padding that makes oneDNN's output size oh (the caller's, which already
// applies ceil_mode): windows end exactly at the last one, never below 0.
int64_t effective_pad_after(int64_t in, int64_t out, int k, int stride, int pad_before) {
  return std::max<int64_t>(0, (out - 1) * stride + k - in - pad_before);
}

// Whether every window lies inside the padded input, where PyTorch's count_include_pad divisor
// is the full kernel size as in oneDNN.
bool windows_inside_padding(const PoolGeometry& g, const Pool2dParams& p) {
  return effective_pad_after(g.h, g.oh, p.kernel_h, p.stride_h, p.pad_top) <= p.pad_bottom &&
         effective_pad_after(g.w, g.ow, p.kernel_w, p.stride_w, p.pad_left) <= p.pad_right;
}

struct PoolEntry {
  dnnl::primitive prim;
};

dnnl::algorithm pool_algorithm(bool max, const Pool2dParams& p) {
  if (max) return dnnl::algorithm::pooling_max;
  return p.count_include_pad ? dnnl::algorithm::pooling_avg_include_padding
                             : dnnl::algorithm::pooling_avg_exclude_padding;
}

CacheKey pool_key(int64_t kind, const PoolGeometry& g, const Pool2dParams& p) {
  CacheKey key;
  key.add(kind).add({g.n, g.c, g.h, g.w, g.oh, g.ow}).add(onednn_threads());
  key.add({p.kernel_h, p.kernel_w, p.stride_h, p.stride_w, p.pad_top, p.pad_left});
  key.add(p.count_include_pad ? 1 : 0);
  return key;
}

// Descriptor pieces shared by the forward and backward primitives.
struct PoolDims {
  dnnl::memory::desc src, dst;
  dnnl::memory::dims strides, kernel, pad_l, pad_r;
};

PoolDims pool_dims(const PoolGeometry& g, const Pool2dParams& p) {
  PoolDims d;
  d.src = dnnl::memory::desc({g.n, g.c, g.h, g.w}, dnnl::memory::data_type::f32, tag::nchw);
  d.dst = dnnl::memory::desc({g.n, g.c, g.oh, g.ow}, dnnl::memory::data_type::f32, tag::nchw);
  d.strides = {p.stride_h, p.stride_w};
  d.kernel = {p.kernel_h, p.kernel_w};
  d.pad_l = {p.pad_top, p.pad_left};
  d.pad_r = {effective_pad_after(g.h, g.oh, p.kernel_h, p.stride_h, p.pad_top),
             effective_pad_after(g.w, g.ow, p.kernel_w, p.stride_w, p.pad_left)};
  return d;
}

dnnl::pooling_forward::primitive_desc forward_pd(const PoolGeometry& g, const Pool2dParams& p,
                                                 bool max) {
  const PoolDims d = pool_dims(g, p);
  dnnl::pooling_forward::desc fd(dnnl::prop_kind::forward_inference, pool_algorithm(max, p), d.src,
                                 d.dst, d.strides, d.kernel, d.pad_l, d.pad_r);
  return dnnl::pooling_forward::primitive_desc(fd, cpu_engine());
}

void run_forward(const Tensor& x, const Tensor& y, const Pool2dParams& p, bool max) {
  static PrimitiveCache<PoolEntry> cache;
  const PoolGeometry g = geometry(x, y);
  PoolEntry& e = cache.get(pool_key(max ? 1 : 2, g, p), [&] {
    auto entry = std::make_unique<PoolEntry>();
    entry->prim = dnnl::pooling_forward(forward_pd(g, p, max));
    return entry;
  });
  const PoolDims d = pool_dims(g, p);
  e.prim.execute(cpu_stream(), {{DNNL_ARG_SRC, tensor_memory(x, d.src)},
                                {DNNL_ARG_DST, tensor_memory(y, d.dst)}});
  cpu_stream().wait();
}

// ---- Hand-written passes ---------------------------------------------------------------------

// Index (in the plane) of the window maximum of output (oy, ox), -1 if the window has no pixel.
inline int64_t window_argmax(const float* plane, const PoolGeometry& g, const Pool2dParams& p,
                             int64_t oy, int64_t ox) {
  int64_t best = -1;
  float best_value = -std::numeric_limits<float>::infinity();
  const int64_t y0 = oy * p.stride_h - p.pad_top, x0 = ox * p.stride_w - p.pad_left;
  for (int64_t iy = std::max<int64_t>(y0, 0); iy < std::min<int64_t>(y0 + p.kernel_h, g.h); ++iy) {
    for (int64_t ix = std::max<int64_t>(x0, 0); ix < std::min<int64_t>(x0 + p.kernel_w, g.w);
         ++ix) {
      const float v = plane[iy * g.w + ix];
      if (best < 0 || v > best_value || std::isnan(v)) {
        best = iy * g.w + ix;
        best_value = v;
      }
    }
  }
  return best;
}

// A window's input range and PyTorch divisor.
struct AvgWindow {
  int64_t y0, y1, x0, x1;
  float inv_divisor;
};

inline AvgWindow avg_window(const PoolGeometry& g, const Pool2dParams& p, int64_t oy, int64_t ox) {
  int64_t y0 = oy * p.stride_h - p.pad_top, x0 = ox * p.stride_w - p.pad_left;
  int64_t y1 = std::min<int64_t>(y0 + p.kernel_h, g.h + p.pad_bottom);
  int64_t x1 = std::min<int64_t>(x0 + p.kernel_w, g.w + p.pad_right);
  const int64_t padded = (y1 - y0) * (x1 - x0);
  y0 = std::max<int64_t>(y0, 0), x0 = std::max<int64_t>(x0, 0);
  y1 = std::min<int64_t>(y1, g.h), x1 = std::min<int64_t>(x1, g.w);
  const int64_t inside = std::max<int64_t>(y1 - y0, 0) * std::max<int64_t>(x1 - x0, 0);
  const int64_t divisor = p.count_include_pad ? padded : inside;
  return {y0, y1, x0, x1, divisor > 0 ? 1.0f / static_cast<float>(divisor) : 0.0f};
}

void max_pool_forward_by_hand(const Tensor& x, const Tensor& y, const Pool2dParams& p) {
  const PoolGeometry g = geometry(x, y);
  const float* xp = x.data<float>();
  float* yp = y.data<float>();
  cpu::parallel_ranges(
      g.planes(), g.oh * g.ow * p.kernel_h * p.kernel_w, [&](int64_t b, int64_t e) {
        for (int64_t pl = b; pl < e; ++pl) {
          const float* plane = xp + pl * g.h * g.w;
          float* out = yp + pl * g.oh * g.ow;
          for (int64_t oy = 0; oy < g.oh; ++oy) {
            for (int64_t ox = 0; ox < g.ow; ++ox) {
              const int64_t best = window_argmax(plane, g, p, oy, ox);
              out[oy * g.ow + ox] =
                  best >= 0 ? plane[best] : -std::numeric_limits<float>::infinity();
            }
          }
        }
      });
}

void avg_pool_forward_by_hand(const Tensor& x, const Tensor& y, const Pool2dParams& p) {
  const PoolGeometry g = geometry(x, y);
  const float* xp = x.data<float>();
  float* yp = y.data<float>();
  cpu::parallel_ranges(g.planes(), g.oh * g.ow * p.kernel_h * p.kernel_w,
                       [&](int64_t b, int64_t e) {
                         for (int64_t pl = b; pl < e; ++pl) {
                           const float* plane = xp + pl * g.h * g.w;
                           float* out = yp + pl * g.oh * g.ow;
                           for (int64_t oy = 0; oy < g.oh; ++oy) {
                             for (int64_t ox = 0; ox < g.ow; ++ox) {
                               const AvgWindow win = avg_window(g, p, oy, ox);
                               float sum = 0.0f;
                               for (int64_t iy = win.y0; iy < win.y1; ++iy) {
                                 for (int64_t ix = win.x0; ix < win.x1; ++ix)
                                   sum += plane[iy * g.w + ix];
                               }
                               out[oy * g.ow + ox] = sum * win.inv_divisor;
                             }
                           }
                         }
                       });
}

void avg_pool_backward_by_hand(const Tensor& gy, const Tensor& gx, const Pool2dParams& p) {
  const PoolGeometry g = geometry(gx, gy);
  const float* gyp = gy.data<float>();
  float* gxp = gx.data<float>();
  cpu::parallel_ranges(g.planes(), g.oh * g.ow * p.kernel_h * p.kernel_w,
                       [&](int64_t b, int64_t e) {
                         for (int64_t pl = b; pl < e; ++pl) {
                           const float* go = gyp + pl * g.oh * g.ow;
                           float* gi = gxp + pl * g.h * g.w;
                           std::fill(gi, gi + g.h * g.w, 0.0f);
                           for (int64_t oy = 0; oy < g.oh; ++oy) {
                             for (int64_t ox = 0; ox < g.ow; ++ox) {
                               const AvgWindow win = avg_window(g, p, oy, ox);
                               const float share = go[oy * g.ow + ox] * win.inv_divisor;
                               for (int64_t iy = win.y0; iy < win.y1; ++iy) {
                                 for (int64_t ix = win.x0; ix < win.x1; ++ix)
                                   gi[iy * g.w + ix] += share;
                               }
                             }
                           }
                         }
                       });
}

// ---- Kernels ---------------------------------------------------------------------------------

// in {x}, out {y}; Pool2dParams.
void max_pool2d(const KernelArgs& a) {
  const Tensor &x = a.in[0], &y = a.out[0];
  check_f32_4d(x, "kernels/cpu/onednn_pool.cpp", "max_pool2d input");
  check_f32_4d(y, "kernels/cpu/onednn_pool.cpp", "max_pool2d output");
  if (y.numel() == 0) return;
  try {
    run_forward(x, y, a.p<Pool2dParams>(), true);
  } catch (const dnnl::error&) {  // a geometry oneDNN declines (e.g. unusual padding)
    max_pool_forward_by_hand(x, y, a.p<Pool2dParams>());
  }
}

// in {gy, x}, out {gx}: each output's gradient goes to its window's first maximum.
void max_pool2d_backward(const KernelArgs& a) {
  const Tensor &gy = a.in[0], &x = a.in[1], &gx = a.out[0];
  check_f32_4d(gy, "kernels/cpu/onednn_pool.cpp", "max_pool2d_backward output gradient");
  check_f32_4d(x, "kernels/cpu/onednn_pool.cpp", "max_pool2d_backward input");
  check_f32_4d(gx, "kernels/cpu/onednn_pool.cpp", "max_pool2d_backward input gradient");
  const Pool2dParams& p = a.p<Pool2dParams>();
  const PoolGeometry g = geometry(x, gy);
  const float* xp = x.data<float>();
  const float* gyp = gy.data<float>();
  float* gxp = gx.data<float>();
  cpu::parallel_ranges(g.planes(), g.oh * g.ow * p.kernel_h * p.kernel_w,
                       [&](int64_t b, int64_t e) {
                         for (int64_t pl = b; pl < e; ++pl) {
                           const float* plane = xp + pl * g.h * g.w;
                           const float* go = gyp + pl * g.oh * g.ow;
                           float* gi = gxp + pl * g.h * g.w;
                           std::fill(gi, gi + g.h * g.w, 0.0f);
                           for (int64_t oy = 0; oy < g.oh; ++oy) {
                             for (int64_t ox = 0; ox < g.ow; ++ox) {
                               const int64_t best = window_argmax(plane, g, p, oy, ox);
                               if (best >= 0) gi[best] += go[oy * g.ow + ox];
                             }
                           }
                         }
                       });
}

// in {x}, out {y}; Pool2dParams.
void avg_pool2d(const KernelArgs& a) {
  const Tensor &x = a.in[0], &y = a.out[0];
  check_f32_4d(x, "kernels/cpu/onednn_pool.cpp", "avg_pool2d input");
  check_f32_4d(y, "kernels/cpu/onednn_pool.cpp", "avg_pool2d output");
  if (y.numel() == 0) return;
  const Pool2dParams& p = a.p<Pool2dParams>();
  if (p.count_include_pad && !windows_inside_padding(geometry(x, y), p)) {
    avg_pool_forward_by_hand(x, y, p);
  } else {
    try {
      run_forward(x, y, p, false);
    } catch (const dnnl::error&) {  // a geometry oneDNN declines
      avg_pool_forward_by_hand(x, y, p);
    }
  }
}

// in {gy}, out {gx}; Pool2dParams.
void avg_pool2d_backward(const KernelArgs& a) {
  static PrimitiveCache<PoolEntry> cache;
  const Tensor &gy = a.in[0], &gx = a.out[0];
  check_f32_4d(gy, "kernels/cpu/onednn_pool.cpp", "avg_pool2d_backward output gradient");
  check_f32_4d(gx, "kernels/cpu/onednn_pool.cpp", "avg_pool2d_backward input gradient");
  if (gx.numel() == 0) return;
  const Pool2dParams& p = a.p<Pool2dParams>();
  const PoolGeometry g = geometry(gx, gy);
  if (gy.numel() == 0 || (p.count_include_pad && !windows_inside_padding(g, p))) {
    avg_pool_backward_by_hand(gy, gx, p);
    return;
  }
  try {
    PoolEntry& e = cache.get(pool_key(3, g, p), [&] {
      const PoolDims d = pool_dims(g, p);
      dnnl::pooling_backward::desc bd(pool_algorithm(false, p), d.src, d.dst, d.strides, d.kernel,
                                      d.pad_l, d.pad_r);
      auto entry = std::make_unique<PoolEntry>();
      entry->prim = dnnl::pooling_backward(
          dnnl::pooling_backward::primitive_desc(bd, cpu_engine(), forward_pd(g, p, false)));
      return entry;
    });
    const PoolDims d = pool_dims(g, p);
    e.prim.execute(cpu_stream(), {{DNNL_ARG_DIFF_DST, tensor_memory(gy, d.dst)},
                                  {DNNL_ARG_DIFF_SRC, tensor_memory(gx, d.src)}});
    cpu_stream().wait();
  } catch (const dnnl::error&) {  // a geometry oneDNN declines
    avg_pool_backward_by_hand(gy, gx, p);
  }
}

}  // namespace

void register_pool_kernels(KernelRegistry& r) {
  r.add(OpId::max_pool2d, DeviceType::cpu, DType::f32, guarded<OpId::max_pool2d, max_pool2d>,
        "onednn");
  r.add(OpId::max_pool2d_backward, DeviceType::cpu, DType::f32,
        guarded<OpId::max_pool2d_backward, max_pool2d_backward>, "onednn");
  r.add(OpId::avg_pool2d, DeviceType::cpu, DType::f32, guarded<OpId::avg_pool2d, avg_pool2d>,
        "onednn");
  r.add(OpId::avg_pool2d_backward, DeviceType::cpu, DType::f32,
        guarded<OpId::avg_pool2d_backward, avg_pool2d_backward>, "onednn");
}

}  // namespace cvd::onednn
