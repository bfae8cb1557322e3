// OpenMP f32 kernels of the contiguous element-wise ops: copy (from any strides, to f32 or f64),
// fill, unary, unary_backward. The math is the shared engine/elementwise_math.h.
#include <algorithm>
#include <cstring>
#include <type_traits>

#include "engine/elementwise_math.h"
#include "kernels/cpu/cpu_op_switch.h"
#include "kernels/cpu/cpu_openmp_families.h"
#include "kernels/cpu/cpu_parallel.h"
#include "kernels/cpu/cpu_strided_rows.h"

namespace cvd::cpu {

namespace {

// dst (contiguous, f32 or f64) = src (f32, any strides incl. broadcast).
template <class D>
void copy_rows(const Tensor& src, const Tensor& dst) {
  const float* s = src.data<float>();
  D* d = dst.data<D>();
  const StridedRows<2> rows = make_strided_rows<2>(dst.shape(), {&dst.strides(), &src.strides()});
  CVD_ASSERT(rows.row_len == 1 || rows.row_stride[0] == 1);
  const int64_t ss = rows.row_stride[1];
  parallel_rows(rows, 1, [&](const std::array<int64_t, 2>& off, int64_t len) {
    D* dp = d + off[0];
    const float* sp = s + off[1];
    if (ss == 1) {
      if constexpr (std::is_same_v<D, float>) {
        std::memcpy(dp, sp, static_cast<size_t>(len) * sizeof(float));
      } else {
        for (int64_t i = 0; i < len; ++i) dp[i] = static_cast<D>(sp[i]);
      }
    } else if (ss == 0) {
      std::fill(dp, dp + len, static_cast<D>(*sp));
    } else {
      for (int64_t i = 0; i < len; ++i) dp[i] = static_cast<D>(sp[i * ss]);
    }
  });
}

// in {src (f32, any strides)}, out {dst (contiguous, f32 or f64, same shape)}.
void copy(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1);
  const Tensor& src = a.in[0];
  const Tensor& dst = a.out[0];
  CVD_ASSERT(src.defined() && src.device().is_cpu() && src.dtype() == DType::f32);
  CVD_ASSERT(dst.defined() && dst.device().is_cpu() && dst.is_contiguous());
  CVD_ASSERT(src.shape() == dst.shape());
  if (dst.dtype() == DType::f32) {
    copy_rows<float>(src, dst);
  } else {
    copy_rows<double>(src, dst);
  }
}

// out {dst}; FillParams.
void fill(const KernelArgs& a) {
  CVD_ASSERT(a.in.empty() && a.out.size() == 1 && a.params != nullptr);
  const Tensor& dst = a.out[0];
  CVD_ASSERT(is_cpu_f32_contiguous(dst));
  const float v = static_cast<float>(a.p<FillParams>().value);
  float* d = dst.data<float>();
  parallel_ranges(dst.numel(), 1, [&](int64_t b, int64_t e) { std::fill(d + b, d + e, v); });
}

// in {x}, out {y}; UnaryParams.
void unary(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1 && a.params != nullptr);
  const Tensor& x = a.in[0];
  const Tensor& y = a.out[0];
  CVD_ASSERT(is_cpu_f32_contiguous(x) && is_cpu_f32_contiguous(y) && x.shape() == y.shape());
  const UnaryParams& p = a.p<UnaryParams>();
  const float pa = static_cast<float>(p.a), pb = static_cast<float>(p.b);
  const float* xp = x.data<float>();
  float* yp = y.data<float>();
  with_unary_op(p.op, [&]<UnaryOp OP>() {
    parallel_ranges(y.numel(), unary_cost(OP), [&](int64_t b, int64_t e) {
      for (int64_t i = b; i < e; ++i) yp[i] = unary_forward<float>(OP, xp[i], pa, pb);
    });
  });
}

// in {gy, x, y}, out {gx}; UnaryParams.
void unary_backward(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 3 && a.out.size() == 1 && a.params != nullptr);
  const Tensor& gy = a.in[0];
  const Tensor& gx = a.out[0];
  CVD_ASSERT(is_cpu_f32_contiguous(gy) && is_cpu_f32_contiguous(gx) && gy.shape() == gx.shape());
  // x or y may be left undefined by a caller whose op does not read it; gy stands in for it.
  const Tensor& x = a.in[1].defined() ? a.in[1] : gy;
  const Tensor& y = a.in[2].defined() ? a.in[2] : gy;
  CVD_ASSERT(is_cpu_f32_contiguous(x) && is_cpu_f32_contiguous(y));
  CVD_ASSERT(x.shape() == gx.shape() && y.shape() == gx.shape());
  const UnaryParams& p = a.p<UnaryParams>();
  const float pa = static_cast<float>(p.a), pb = static_cast<float>(p.b);
  const float* gyp = gy.data<float>();
  const float* xp = x.data<float>();
  const float* yp = y.data<float>();
  float* gxp = gx.data<float>();
  with_unary_op(p.op, [&]<UnaryOp OP>() {
    parallel_ranges(gx.numel(), unary_cost(OP), [&](int64_t b, int64_t e) {
      for (int64_t i = b; i < e; ++i) {
        gxp[i] = cvd::unary_backward<float>(OP, gyp[i], xp[i], yp[i], pa, pb);
      }
    });
  });
}

}  // namespace

void register_pointwise_kernels(KernelRegistry& r) {
  r.add(OpId::copy, DeviceType::cpu, DType::f32, copy, "openmp");
  r.add(OpId::fill, DeviceType::cpu, DType::f32, fill, "openmp");
  r.add(OpId::unary, DeviceType::cpu, DType::f32, unary, "openmp");
  r.add(OpId::unary_backward, DeviceType::cpu, DType::f32, unary_backward, "openmp");
}

}  // namespace cvd::cpu
