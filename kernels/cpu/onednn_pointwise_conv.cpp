// Pointwise (1x1, stride 1, unpadded, ungrouped) convolutions on the NCHW tensors themselves.
// With P = H * W pixels, per image n:
//   forward:          y_n [O, P] = W [O, C] x_n [C, P] + b      (W broadcast over the batch)
//   backward data:    gx_n [C, P] = W^T [C, O] gy_n [O, P]      (W^T as strides, no copy)
//   backward weights: gW [O, C] = sum_n gy_n [O, P] x_n^T [P, C] (batched, then summed over n)
// On images of at least 64x64 pixels (use_pointwise_gemm()) the forward and backward-data products
// run as oneDNN's sgemm, one call per image, or on our AVX-512 kernel (cpu/pointwise_gemm.h) where
// use_pointwise_kernel() says so (AVX-512F, 128x128 pixels or more, sums over 64-128 channels or
// over 16-63 into 64 or more); smaller images and backward weights run as oneDNN matmul primitives.
// History of the choice (bench/bench_conv.cpp): the matmul primitive beat oneDNN's blocked 1x1
// convolution even before counting its reorders on small images (1x1_96-576_16x20); on Mannequin's
// full-resolution shape (1x1_128-64_224x384) oneDNN's convolution on data already in its layout
// was ~2x faster than sgemm or the matmul, and with the reorders every other convolution pays it
// still beat sgemm in the forward pass there (1.3-1.5x), tied in backward data and lost elsewhere
// (0.7x at 112x192 with 256 channels, 0.23-0.39x on the default network's narrow layers; bench
// variant ours_conv, 2026-12-06). oneDNN 2.6's f32 matmul on these plain layouts runs the same
// sgemm kernel (results bitwise equal). Adding the bias per cache-sized column block instead of in
// a separate pass gained nothing measurable for sgemm (tried). Our kernel, which adds the bias in
// its registers, streams its output and packs the input in strips, ran that shape's forward and
// backward data at ~2x sgemm (2026-12-07, the README's conv table).
#include <cstring>
#include <vector>

#include "engine/error.h"
#include "kernels/cpu/cpu_parallel.h"
#include "kernels/cpu/onednn_conv_family.h"
#include "kernels/cpu/pointwise_gemm.h"

namespace cvd::onednn {

namespace {

using dims = dnnl::memory::dims;

dnnl::memory::desc f32(const dims& d, const dims& strides) {
  return dnnl::memory::desc(d, dnnl::memory::data_type::f32, strides);
}

struct MatmulPlan {
  dnnl::matmul prim;
  dnnl::memory::desc src, weights, dst;
};

enum class Pass : int64_t { forward = 1, backward_data = 2, backward_weights = 3 };

// The matmul of one pass; n images, o output and c input channels, p pixels.
MatmulPlan& plan(Pass pass, int64_t n, int64_t o, int64_t c, int64_t p) {
  static PrimitiveCache<MatmulPlan> cache;
  CacheKey key;
  key.add(static_cast<int64_t>(pass)).add({n, o, c, p}).add(onednn_threads());
  return cache.get(key, [&] {
    auto e = std::make_unique<MatmulPlan>();
    switch (pass) {
      case Pass::forward:
        e->src = f32({1, o, c}, {o * c, c, 1});
        e->weights = f32({n, c, p}, {c * p, p, 1});
        e->dst = f32({n, o, p}, {o * p, p, 1});
        break;
      case Pass::backward_data:
        e->src = f32({1, c, o}, {o * c, 1, c});  // W^T
        e->weights = f32({n, o, p}, {o * p, p, 1});
        e->dst = f32({n, c, p}, {c * p, p, 1});
        break;
      case Pass::backward_weights:
        e->src = f32({n, o, p}, {o * p, p, 1});
        e->weights = f32({n, p, c}, {c * p, 1, p});  // x_n^T
        e->dst = f32({n, o, c}, {o * c, c, 1});
        break;
    }
    e->prim = dnnl::matmul(
        dnnl::matmul::primitive_desc(dnnl::matmul::desc(e->src, e->weights, e->dst), cpu_engine()));
    return e;
  });
}

dnnl::memory memory_of(const Tensor& t, const dnnl::memory::desc& md) {
  return dnnl::memory(md, cpu_engine(), t.data_ptr());
}

// Row-major C [m, n] = op(A) [m, k] x B [k, n] with B and C dense (ldb = ldc = n), A [m, k]
// ('N', lda = k) or its transpose stored as [k, m] ('T', lda = m).
void sgemm(char transa, int64_t m, int64_t n, int64_t k, const float* a, const float* b, float* c) {
  const dnnl_status_t st =
      dnnl_sgemm(transa, 'N', m, n, k, 1.0f, a, transa == 'N' ? k : m, b, n, 0.0f, c, n);
  CVD_CHECK(st == dnnl_success, "kernels/cpu/onednn_pointwise_conv.cpp: dnnl_sgemm failed ({})",
            static_cast<int>(st));
}

}  // namespace

void pointwise_conv_forward(const Tensor& x, const Tensor& w, const Tensor& b, const Tensor& y) {
  const int64_t n = x.size(0), c = x.size(1), o = y.size(1), p = x.size(2) * x.size(3);
  if (use_pointwise_kernel(p, c, o)) {
    cpu::PointwiseGemm g;
    g.n = n, g.m = o, g.k = c, g.p = p;
    g.a = w.data<float>(), g.a_row = c, g.a_col = 1;
    g.b = x.data<float>(), g.c = y.data<float>();
    g.bias = b.defined() ? b.data<float>() : nullptr;
    cpu::pointwise_gemm(g);
    return;
  }
  if (use_pointwise_gemm(p, c)) {
    for (int64_t i = 0; i < n; ++i)
      sgemm('N', o, p, c, w.data<float>(), x.data<float>() + i * c * p,
            y.data<float>() + i * o * p);
  } else {
    MatmulPlan& e = plan(Pass::forward, n, o, c, p);
    e.prim.execute(cpu_stream(), {{DNNL_ARG_SRC, memory_of(w, e.src)},
                                  {DNNL_ARG_WEIGHTS, memory_of(x, e.weights)},
                                  {DNNL_ARG_DST, memory_of(y, e.dst)}});
    cpu_stream().wait();
  }
  if (!b.defined()) return;
  // The bias runs along the rows (M) of each product: oneDNN 2.6 serves that bias (or a
  // broadcast binary post-op) only with slower kernels than this separate pass (measured).
  const float* bp = b.data<float>();
  float* yp = y.data<float>();
  cpu::parallel_ranges(n * o, p, [&](int64_t begin, int64_t end) {
    for (int64_t r = begin; r < end; ++r) {
      const float v = bp[r % o];
      float* row = yp + r * p;
      for (int64_t k = 0; k < p; ++k) row[k] += v;
    }
  });
}

void pointwise_conv_backward_data(const Tensor& gy, const Tensor& w, const Tensor& gx) {
  const int64_t n = gx.size(0), c = gx.size(1), o = gy.size(1), p = gx.size(2) * gx.size(3);
  if (use_pointwise_kernel(p, o, c)) {  // gx_n = W^T gy_n: A (m = c, k = o) at w[o * C + c]
    cpu::PointwiseGemm g;
    g.n = n, g.m = c, g.k = o, g.p = p;
    g.a = w.data<float>(), g.a_row = 1, g.a_col = c;
    g.b = gy.data<float>(), g.c = gx.data<float>();
    cpu::pointwise_gemm(g);
    return;
  }
  if (use_pointwise_gemm(p, o)) {
    for (int64_t i = 0; i < n; ++i)  // gx_n = W^T gy_n, W stored [O, C]
      sgemm('T', c, p, o, w.data<float>(), gy.data<float>() + i * o * p,
            gx.data<float>() + i * c * p);
    return;
  }
  MatmulPlan& e = plan(Pass::backward_data, n, o, c, p);
  e.prim.execute(cpu_stream(), {{DNNL_ARG_SRC, memory_of(w, e.src)},
                                {DNNL_ARG_WEIGHTS, memory_of(gy, e.weights)},
                                {DNNL_ARG_DST, memory_of(gx, e.dst)}});
  cpu_stream().wait();
}

void pointwise_conv_backward_weight(const Tensor& gy, const Tensor& x, const Tensor& gw,
                                    const Tensor& gb) {
  const int64_t n = x.size(0), c = x.size(1), o = gy.size(1), p = x.size(2) * x.size(3);
  MatmulPlan& e = plan(Pass::backward_weights, n, o, c, p);
  // One product per image into scratch (straight into gw for a single image), then summed.
  float* per_image =
      n == 1 ? gw.data<float>() : static_cast<float*>(scratch_buffer(0, e.dst.get_size()));
  e.prim.execute(cpu_stream(), {{DNNL_ARG_SRC, memory_of(gy, e.src)},
                                {DNNL_ARG_WEIGHTS, memory_of(x, e.weights)},
                                {DNNL_ARG_DST, dnnl::memory(e.dst, cpu_engine(), per_image)}});
  cpu_stream().wait();
  float* gwp = gw.data<float>();
  const float* gyp = gy.data<float>();
  float* gbp = gb.defined() ? gb.data<float>() : nullptr;
  cpu::parallel_ranges(o, n * (c + p), [&](int64_t begin, int64_t end) {
    for (int64_t oc = begin; oc < end; ++oc) {
      if (n > 1) {
        float* row = gwp + oc * c;
        std::memcpy(row, per_image + oc * c, c * sizeof(float));
        for (int64_t img = 1; img < n; ++img) {
          const float* src = per_image + (img * o + oc) * c;
          for (int64_t k = 0; k < c; ++k) row[k] += src[k];
        }
      }
      if (gbp != nullptr) {
        double sum = 0.0;
        for (int64_t img = 0; img < n; ++img) {
          const float* g = gyp + (img * o + oc) * p;
          float partial = 0.0f;
#pragma omp simd reduction(+ : partial)
          for (int64_t k = 0; k < p; ++k) partial += g[k];
          sum += partial;
        }
        gbp[oc] = static_cast<float>(sum);
      }
    }
  });
}

}  // namespace cvd::onednn
