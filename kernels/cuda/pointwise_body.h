// CUDA kernel bodies and op drivers of the element-wise ops: copy (strided source, f32 <-> f64),
// fill, unary, unary_backward, binary and where (broadcast views), adam_update, sgd_update.
// One thread per output element; the math is engine/elementwise_math.h, shared with the CPU.
#pragma once
#include "engine/dispatch.h"
#include "engine/kernel_params.h"
#include "kernels/cuda/launch_body.h"

namespace cvd::cuda {

template <class S, class D>
struct CopyBody {
  const S* src;
  ViewGeometry src_view;
  D* dst;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    dst[i] = static_cast<D>(src[src_view.offset(i)]);
  }
};

template <class T>
struct FillBody {
  T* dst;
  T value;
  CVD_HOST_DEVICE void operator()(int64_t i) const { dst[i] = value; }
};

template <class T>
struct UnaryBody {
  const T* x;
  T* y;
  UnaryOp op;
  T a, b;
  CVD_HOST_DEVICE void operator()(int64_t i) const { y[i] = unary_forward<T>(op, x[i], a, b); }
};

template <class T>
struct UnaryBackwardBody {
  const T *gy, *x, *y;
  T* gx;
  UnaryOp op;
  T a, b;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    gx[i] = cvd::unary_backward<T>(op, gy[i], x[i], y[i], a, b);
  }
};

template <class T>
struct BinaryBody {
  const T *a, *b;
  ViewGeometry a_view, b_view;
  T* c;
  BinaryOp op;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    c[i] = binary_forward<T>(op, a[a_view.offset(i)], b[b_view.offset(i)]);
  }
};

template <class C, class T>
struct WhereBody {
  const C* cond;
  const T *a, *b;
  ViewGeometry cond_view, a_view, b_view;
  T* c;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    c[i] = cond[cond_view.offset(i)] != C(0) ? a[a_view.offset(i)] : b[b_view.offset(i)];
  }
};

template <class T>
struct AdamBody {
  T *p, *m, *v;
  const T* g;
  T beta1, beta2, eps, weight_decay, step_size, bc2_sqrt;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    adam_update_element<T>(p[i], g[i], m[i], v[i], beta1, beta2, eps, weight_decay, step_size,
                           bc2_sqrt);
  }
};

template <class T>
struct SgdBody {
  T *p, *buf;
  const T* g;
  T lr, momentum, dampening, weight_decay;
  bool nesterov, first_step;
  CVD_HOST_DEVICE void operator()(int64_t i) const {
    T unused = T(0);
    T& b = buf ? buf[i] : unused;
    sgd_update_element<T>(p[i], g[i], b, lr, momentum, dampening, weight_decay, nesterov,
                          first_step);
  }
};

// ---- Op drivers: unpack KernelArgs (see engine/dispatch.h) and launch the bodies ---------------

template <class Launch, class S, class D>
void copy_typed(const Tensor& src, const Tensor& dst) {
  Launch::launch(dst.numel(), CopyBody<S, D>{src.data<S>(), view_geometry(src), dst.data<D>()});
}

// in {src (any strides, f32/f64)}, out {dst (contiguous, f32/f64)}.
template <class Launch>
void copy_op(const KernelArgs& a) {
  const Tensor &src = a.in[0], &dst = a.out[0];
  CVD_ASSERT(src.shape() == dst.shape() && dst.is_contiguous());
  const bool s64 = src.dtype() == DType::f64, d64 = dst.dtype() == DType::f64;
  if (s64 && d64) copy_typed<Launch, double, double>(src, dst);
  if (s64 && !d64) copy_typed<Launch, double, float>(src, dst);
  if (!s64 && d64) copy_typed<Launch, float, double>(src, dst);
  if (!s64 && !d64) copy_typed<Launch, float, float>(src, dst);
}

template <class Launch>
void fill_op(const KernelArgs& a) {
  const Tensor& dst = a.out[0];
  const double v = a.p<FillParams>().value;
  if (dst.dtype() == DType::f64) {
    Launch::launch(dst.numel(), FillBody<double>{dst.data<double>(), v});
  } else {
    Launch::launch(dst.numel(), FillBody<float>{dst.data<float>(), static_cast<float>(v)});
  }
}

template <class Launch>
void unary_op(const KernelArgs& a) {
  const UnaryParams& p = a.p<UnaryParams>();
  Launch::launch(a.out[0].numel(),
                 UnaryBody<float>{a.in[0].data<float>(), a.out[0].data<float>(), p.op,
                                  static_cast<float>(p.a), static_cast<float>(p.b)});
}

template <class Launch>
void unary_backward_op(const KernelArgs& a) {
  const UnaryParams& p = a.p<UnaryParams>();
  // x or y may be undefined when the op does not read it (unary_backward_reads); gy stands in.
  const Tensor& x = a.in[1].defined() ? a.in[1] : a.in[0];
  const Tensor& y = a.in[2].defined() ? a.in[2] : a.in[0];
  Launch::launch(a.out[0].numel(),
                 UnaryBackwardBody<float>{a.in[0].data<float>(), x.data<float>(), y.data<float>(),
                                          a.out[0].data<float>(), p.op, static_cast<float>(p.a),
                                          static_cast<float>(p.b)});
}

template <class Launch>
void binary_op(const KernelArgs& args) {
  const Tensor &a = args.in[0], &b = args.in[1], &c = args.out[0];
  Launch::launch(c.numel(),
                 BinaryBody<float>{a.data<float>(), b.data<float>(), view_geometry(a),
                                   view_geometry(b), c.data<float>(), args.p<BinaryParams>().op});
}

template <class Launch, class C>
void where_typed(const KernelArgs& args) {
  const Tensor &cond = args.in[0], &a = args.in[1], &b = args.in[2], &c = args.out[0];
  Launch::launch(c.numel(), WhereBody<C, float>{cond.data<C>(), a.data<float>(), b.data<float>(),
                                                view_geometry(cond), view_geometry(a),
                                                view_geometry(b), c.data<float>()});
}

// in {cond (f32 or f64), a, b}, out {c}.
template <class Launch>
void where_op(const KernelArgs& args) {
  if (args.in[0].dtype() == DType::f64) {
    where_typed<Launch, double>(args);
  } else {
    where_typed<Launch, float>(args);
  }
}

// in {param, grad, m, v}; AdamParams.
template <class Launch>
void adam_update_op(const KernelArgs& a) {
  const AdamParams& p = a.p<AdamParams>();
  const double t = static_cast<double>(p.step);
  const double step_size = p.lr / (1.0 - std::pow(p.beta1, t));
  const double bc2_sqrt = std::sqrt(1.0 - std::pow(p.beta2, t));
  Launch::launch(a.in[0].numel(),
                 AdamBody<float>{a.in[0].data<float>(), a.in[2].data<float>(),
                                 a.in[3].data<float>(), a.in[1].data<float>(),
                                 static_cast<float>(p.beta1), static_cast<float>(p.beta2),
                                 static_cast<float>(p.eps), static_cast<float>(p.weight_decay),
                                 static_cast<float>(step_size), static_cast<float>(bc2_sqrt)});
}

// in {param, grad, buf (may be undefined when momentum == 0)}; SgdParams.
template <class Launch>
void sgd_update_op(const KernelArgs& a) {
  const SgdParams& p = a.p<SgdParams>();
  float* buf = a.in.size() > 2 ? data_or_null<float>(a.in[2]) : nullptr;
  Launch::launch(
      a.in[0].numel(),
      SgdBody<float>{a.in[0].data<float>(), buf, a.in[1].data<float>(), static_cast<float>(p.lr),
                     static_cast<float>(p.momentum), static_cast<float>(p.dampening),
                     static_cast<float>(p.weight_decay), p.nesterov, p.first_step});
}

}  // namespace cvd::cuda
