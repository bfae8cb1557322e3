// OpenMP f32 kernels of the broadcasting element-wise ops: binary and where. Their inputs are
// views with the output's shape and any strides (0 where broadcast). The dims are coalesced
// (kernels/cpu/cpu_strided_rows.h) and each row runs a loop specialised for its input strides:
// contiguous, scalar (stride 0) or general.
#include "engine/elementwise_math.h"
#include "kernels/cpu/cpu_op_switch.h"
#include "kernels/cpu/cpu_openmp_families.h"
#include "kernels/cpu/cpu_strided_rows.h"

namespace cvd::cpu {

namespace {

// One row of c = op(a, b): c contiguous, a and b with strides sa, sb.
template <BinaryOp OP>
void binary_row(const float* a, int64_t sa, const float* b, int64_t sb, float* c, int64_t n) {
  if (sa == 1 && sb == 1) {
    for (int64_t i = 0; i < n; ++i) c[i] = binary_forward<float>(OP, a[i], b[i]);
  } else if (sa == 1 && sb == 0) {
    const float bv = *b;
    for (int64_t i = 0; i < n; ++i) c[i] = binary_forward<float>(OP, a[i], bv);
  } else if (sa == 0 && sb == 1) {
    const float av = *a;
    for (int64_t i = 0; i < n; ++i) c[i] = binary_forward<float>(OP, av, b[i]);
  } else {
    for (int64_t i = 0; i < n; ++i) c[i] = binary_forward<float>(OP, a[i * sa], b[i * sb]);
  }
}

void check_view(const Tensor& t, const Tensor& out) {
  CVD_ASSERT(t.defined() && t.device().is_cpu() && t.dtype() == DType::f32);
  CVD_ASSERT(t.shape() == out.shape());
}

void check_output(const Tensor& c) {
  CVD_ASSERT(c.defined() && c.device().is_cpu() && c.dtype() == DType::f32 && c.is_contiguous());
}

// in {a, b} (views of c's shape, any strides), out {c}; BinaryParams.
void binary(const KernelArgs& args) {
  CVD_ASSERT(args.in.size() == 2 && args.out.size() == 1 && args.params != nullptr);
  const Tensor& a = args.in[0];
  const Tensor& b = args.in[1];
  const Tensor& c = args.out[0];
  check_output(c);
  check_view(a, c);
  check_view(b, c);
  const StridedRows<3> rows =
      make_strided_rows<3>(c.shape(), {&c.strides(), &a.strides(), &b.strides()});
  CVD_ASSERT(rows.row_len == 1 || rows.row_stride[0] == 1);
  const float* ap = a.data<float>();
  const float* bp = b.data<float>();
  float* cp = c.data<float>();
  const int64_t sa = rows.row_stride[1], sb = rows.row_stride[2];
  with_binary_op(args.p<BinaryParams>().op, [&]<BinaryOp OP>() {
    parallel_rows(rows, OP == BinaryOp::div ? 4 : 1,
                  [&](const std::array<int64_t, 3>& off, int64_t len) {
                    binary_row<OP>(ap + off[1], sa, bp + off[2], sb, cp + off[0], len);
                  });
  });
}

// One row of c = cond != 0 ? a : b.
template <class C>
void where_row(const C* cond, int64_t sc, const float* a, int64_t sa, const float* b, int64_t sb,
               float* c, int64_t n) {
  if (sc == 1 && sa == 1 && sb == 1) {
    for (int64_t i = 0; i < n; ++i) c[i] = cond[i] != C(0) ? a[i] : b[i];
  } else if (sc == 0) {
    const float* src = *cond != C(0) ? a : b;
    const int64_t s = *cond != C(0) ? sa : sb;
    if (s == 1) {
      for (int64_t i = 0; i < n; ++i) c[i] = src[i];
    } else {
      for (int64_t i = 0; i < n; ++i) c[i] = src[i * s];
    }
  } else if (sc == 1 && sa == 1 && sb == 0) {
    const float bv = *b;
    for (int64_t i = 0; i < n; ++i) c[i] = cond[i] != C(0) ? a[i] : bv;
  } else if (sc == 1 && sa == 0 && sb == 1) {
    const float av = *a;
    for (int64_t i = 0; i < n; ++i) c[i] = cond[i] != C(0) ? av : b[i];
  } else {
    for (int64_t i = 0; i < n; ++i) c[i] = cond[i * sc] != C(0) ? a[i * sa] : b[i * sb];
  }
}

template <class C>
void where_typed(const Tensor& cond, const Tensor& a, const Tensor& b, const Tensor& c) {
  const StridedRows<4> rows =
      make_strided_rows<4>(c.shape(), {&c.strides(), &cond.strides(), &a.strides(), &b.strides()});
  CVD_ASSERT(rows.row_len == 1 || rows.row_stride[0] == 1);
  const C* condp = cond.data<C>();
  const float* ap = a.data<float>();
  const float* bp = b.data<float>();
  float* cp = c.data<float>();
  const int64_t sc = rows.row_stride[1], sa = rows.row_stride[2], sb = rows.row_stride[3];
  parallel_rows(rows, 1, [&](const std::array<int64_t, 4>& off, int64_t len) {
    where_row<C>(condp + off[1], sc, ap + off[2], sa, bp + off[3], sb, cp + off[0], len);
  });
}

// in {cond (f32 or f64), a, b} (views of c's shape, any strides), out {c}: cond != 0 ? a : b.
void where(const KernelArgs& args) {
  CVD_ASSERT(args.in.size() == 3 && args.out.size() == 1);
  const Tensor& cond = args.in[0];
  const Tensor& c = args.out[0];
  check_output(c);
  CVD_ASSERT(cond.defined() && cond.device().is_cpu() && cond.shape() == c.shape());
  check_view(args.in[1], c);
  check_view(args.in[2], c);
  if (cond.dtype() == DType::f32) {
    where_typed<float>(cond, args.in[1], args.in[2], c);
  } else {
    where_typed<double>(cond, args.in[1], args.in[2], c);
  }
}

}  // namespace

void register_broadcast_kernels(KernelRegistry& r) {
  r.add(OpId::binary, DeviceType::cpu, DType::f32, binary, "openmp");
  r.add(OpId::where, DeviceType::cpu, DType::f32, where, "openmp");
}

}  // namespace cvd::cpu
