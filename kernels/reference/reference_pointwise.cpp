// Reference kernels of the element-wise ops: unary, unary_backward, binary, where. The math is the
// shared engine/elementwise_math.h, evaluated in double.
#include "engine/elementwise_math.h"
#include "engine/kernel_params.h"
#include "kernels/reference/reference_access.h"
#include "kernels/reference/reference_kernels.h"

namespace cvd::reference {

// in {x}, out {y}; UnaryParams.
void unary(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1 && a.params != nullptr);
  const Tensor& x = a.in[0];
  const Tensor& y = a.out[0];
  CVD_ASSERT(is_f64_contiguous(x) && is_f64_contiguous(y) && x.shape() == y.shape());
  const UnaryParams& p = a.p<UnaryParams>();
  const double* xp = x.data<double>();
  double* yp = y.data<double>();
  for (int64_t i = 0; i < y.numel(); ++i) yp[i] = unary_forward<double>(p.op, xp[i], p.a, p.b);
}

// in {gy, x, y}, out {gx}; UnaryParams.
void unary_backward(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 3 && a.out.size() == 1 && a.params != nullptr);
  const Tensor& gy = a.in[0];
  // x or y may be undefined when the op does not read it (unary_backward_reads); gy stands in.
  const Tensor& x = a.in[1].defined() ? a.in[1] : gy;
  const Tensor& y = a.in[2].defined() ? a.in[2] : gy;
  const Tensor& gx = a.out[0];
  CVD_ASSERT(is_f64_contiguous(gy) && is_f64_contiguous(x) && is_f64_contiguous(y));
  CVD_ASSERT(is_f64_contiguous(gx));
  CVD_ASSERT(gy.shape() == gx.shape() && x.shape() == gx.shape() && y.shape() == gx.shape());
  const UnaryParams& p = a.p<UnaryParams>();
  const double* gyp = gy.data<double>();
  const double* xp = x.data<double>();
  const double* yp = y.data<double>();
  double* gxp = gx.data<double>();
  for (int64_t i = 0; i < gx.numel(); ++i) {
    gxp[i] = cvd::unary_backward<double>(p.op, gyp[i], xp[i], yp[i], p.a, p.b);
  }
}

// in {a, b} (views of c's shape, any strides), out {c}; BinaryParams.
void binary(const KernelArgs& args) {
  CVD_ASSERT(args.in.size() == 2 && args.out.size() == 1 && args.params != nullptr);
  const Tensor& a = args.in[0];
  const Tensor& b = args.in[1];
  const Tensor& c = args.out[0];
  CVD_ASSERT(is_f64_contiguous(c));
  CVD_ASSERT(a.defined() && a.device().is_cpu() && a.dtype() == DType::f64);
  CVD_ASSERT(b.defined() && b.device().is_cpu() && b.dtype() == DType::f64);
  CVD_ASSERT(a.shape() == c.shape() && b.shape() == c.shape());
  const BinaryOp op = args.p<BinaryParams>().op;
  const double* ap = a.data<double>();
  const double* bp = b.data<double>();
  double* cp = c.data<double>();
  for (int64_t i = 0; i < c.numel(); ++i) {
    cp[i] = binary_forward<double>(op, ap[strided_offset(a, i)], bp[strided_offset(b, i)]);
  }
}

// in {cond, a, b} (views of c's shape, any strides; cond f32 or f64), out {c}: cond != 0 ? a : b.
void where(const KernelArgs& args) {
  CVD_ASSERT(args.in.size() == 3 && args.out.size() == 1);
  const Tensor& cond = args.in[0];
  const Tensor& a = args.in[1];
  const Tensor& b = args.in[2];
  const Tensor& c = args.out[0];
  CVD_ASSERT(is_f64_contiguous(c));
  CVD_ASSERT(cond.defined() && cond.device().is_cpu());
  CVD_ASSERT(a.defined() && a.device().is_cpu() && a.dtype() == DType::f64);
  CVD_ASSERT(b.defined() && b.device().is_cpu() && b.dtype() == DType::f64);
  CVD_ASSERT(cond.shape() == c.shape() && a.shape() == c.shape() && b.shape() == c.shape());
  const double* ap = a.data<double>();
  const double* bp = b.data<double>();
  double* cp = c.data<double>();
  for (int64_t i = 0; i < c.numel(); ++i) {
    const bool take_a = load_as_double(cond, strided_offset(cond, i)) != 0.0;
    cp[i] = take_a ? ap[strided_offset(a, i)] : bp[strided_offset(b, i)];
  }
}

}  // namespace cvd::reference
