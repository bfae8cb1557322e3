// Reference kernels of the tensor plumbing ops: copy, fill, reduce_sum, concat, pad, matmul.
#include <vector>

#include "engine/kernel_params.h"
#include "kernels/reference/reference_access.h"
#include "kernels/reference/reference_kernels.h"

namespace cvd::reference {

// in {src (any strides, f32/f64)}, out {dst (contiguous, f32/f64, same shape)}.
void copy(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1);
  const Tensor& src = a.in[0];
  const Tensor& dst = a.out[0];
  CVD_ASSERT(src.defined() && dst.defined());
  CVD_ASSERT(src.device().is_cpu() && dst.device().is_cpu());
  CVD_ASSERT(src.shape() == dst.shape());
  CVD_ASSERT(dst.is_contiguous());
  const int64_t n = dst.numel();
  for (int64_t i = 0; i < n; ++i)
    store_from_double(dst, i, load_as_double(src, strided_offset(src, i)));
}

// out {dst}; FillParams.
void fill(const KernelArgs& a) {
  CVD_ASSERT(a.in.empty() && a.out.size() == 1 && a.params != nullptr);
  const Tensor& dst = a.out[0];
  CVD_ASSERT(dst.defined() && dst.device().is_cpu() && dst.is_contiguous());
  const double value = a.p<FillParams>().value;
  const int64_t n = dst.numel();
  for (int64_t i = 0; i < n; ++i) store_from_double(dst, i, value);
}

// in {x}, out {y}: y = x summed over ReduceParams::dims, which are removed from the shape.
void reduce_sum(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1 && a.params != nullptr);
  const Tensor& x = a.in[0];
  const Tensor& y = a.out[0];
  CVD_ASSERT(is_f64_contiguous(x) && is_f64_contiguous(y));
  const std::vector<int>& dims = a.p<ReduceParams>().dims;
  std::vector<bool> reduced(x.dim(), false);
  for (size_t i = 0; i < dims.size(); ++i) {
    CVD_ASSERT(dims[i] >= 0 && dims[i] < x.dim());
    CVD_ASSERT(i == 0 || dims[i] > dims[i - 1]);
    reduced[dims[i]] = true;
  }
  Shape kept_shape;
  for (int d = 0; d < x.dim(); ++d) {
    if (!reduced[d]) kept_shape.push_back(x.shape()[d]);
  }
  CVD_ASSERT(y.numel() == shape_numel(kept_shape));

  const double* xp = x.data<double>();
  double* yp = y.data<double>();
  for (int64_t j = 0; j < y.numel(); ++j) yp[j] = 0.0;
  std::vector<int64_t> index(x.dim(), 0);  // multi-index of element i of x
  for (int64_t i = 0; i < x.numel(); ++i) {
    int64_t out = 0;
    for (int d = 0; d < x.dim(); ++d) {
      if (!reduced[d]) out = out * x.shape()[d] + index[d];
    }
    yp[out] += xp[i];
    for (int d = x.dim() - 1; d >= 0; --d) {  // advance the multi-index
      if (++index[d] < x.shape()[d]) break;
      index[d] = 0;
    }
  }
}

// in {x0..xn}, out {y}: inputs stacked along ConcatParams::dim.
void concat(const KernelArgs& a) {
  CVD_ASSERT(!a.in.empty() && a.out.size() == 1 && a.params != nullptr);
  const Tensor& y = a.out[0];
  CVD_ASSERT(is_f64_contiguous(y));
  const int dim = a.p<ConcatParams>().dim;
  CVD_ASSERT(dim >= 0 && dim < y.dim());
  const int64_t outer = dims_product(y.shape(), 0, dim);
  const int64_t inner = dims_product(y.shape(), dim + 1, y.dim());
  const int64_t y_len = y.shape()[dim];
  double* yp = y.data<double>();
  int64_t start = 0;  // position of the current input along dim
  for (const Tensor& x : a.in) {
    CVD_ASSERT(is_f64_contiguous(x) && x.dim() == y.dim());
    for (int d = 0; d < y.dim(); ++d) CVD_ASSERT(d == dim || x.shape()[d] == y.shape()[d]);
    const int64_t x_len = x.shape()[dim];
    const double* xp = x.data<double>();
    for (int64_t o = 0; o < outer; ++o) {
      for (int64_t k = 0; k < x_len; ++k) {
        for (int64_t i = 0; i < inner; ++i) {
          yp[(o * y_len + start + k) * inner + i] = xp[(o * x_len + k) * inner + i];
        }
      }
    }
    start += x_len;
  }
  CVD_ASSERT(start == y_len);
}

// in {x}, out {y}: y = x surrounded by PadParams::value, before[d] / after[d] elements per dim.
void pad(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1 && a.params != nullptr);
  const Tensor& x = a.in[0];
  const Tensor& y = a.out[0];
  const PadParams& p = a.p<PadParams>();
  CVD_ASSERT(is_f64_contiguous(x) && is_f64_contiguous(y) && x.dim() == y.dim());
  CVD_ASSERT(p.before.size() == static_cast<size_t>(x.dim()));
  CVD_ASSERT(p.after.size() == static_cast<size_t>(x.dim()));
  for (int d = 0; d < x.dim(); ++d) {
    CVD_ASSERT(p.before[d] >= 0 && p.after[d] >= 0);
    CVD_ASSERT(y.shape()[d] == p.before[d] + x.shape()[d] + p.after[d]);
  }
  double* yp = y.data<double>();
  const double* xp = x.data<double>();
  for (int64_t j = 0; j < y.numel(); ++j) yp[j] = p.value;
  std::vector<int64_t> index(x.dim(), 0);  // multi-index of element i of x
  for (int64_t i = 0; i < x.numel(); ++i) {
    int64_t out = 0;
    for (int d = 0; d < x.dim(); ++d) out = out * y.shape()[d] + index[d] + p.before[d];
    yp[out] = xp[i];
    for (int d = x.dim() - 1; d >= 0; --d) {
      if (++index[d] < x.shape()[d]) break;
      index[d] = 0;
    }
  }
}

// in {a [B,M,K] (or [B,K,M] if trans_a), b [B or 1,K,N] (or [B or 1,N,K] if trans_b)},
// out {c [B,M,N]}: c[i] = op(a[i]) op(b[i or 0]).
void matmul(const KernelArgs& args) {
  CVD_ASSERT(args.in.size() == 2 && args.out.size() == 1 && args.params != nullptr);
  const Tensor& a = args.in[0];
  const Tensor& b = args.in[1];
  const Tensor& c = args.out[0];
  const MatmulParams& p = args.p<MatmulParams>();
  CVD_ASSERT(is_f64_contiguous(a) && is_f64_contiguous(b) && is_f64_contiguous(c));
  CVD_ASSERT(a.dim() == 3 && b.dim() == 3 && c.dim() == 3);
  const int64_t batch = c.shape()[0], m = c.shape()[1], n = c.shape()[2];
  const int64_t k = p.trans_a ? a.shape()[1] : a.shape()[2];
  CVD_ASSERT(a.shape()[0] == batch);
  CVD_ASSERT((p.trans_a ? a.shape()[2] : a.shape()[1]) == m);
  CVD_ASSERT(b.shape()[0] == batch || b.shape()[0] == 1);
  CVD_ASSERT((p.trans_b ? b.shape()[2] : b.shape()[1]) == k);
  CVD_ASSERT((p.trans_b ? b.shape()[1] : b.shape()[2]) == n);
  const double* ap = a.data<double>();
  const double* bp = b.data<double>();
  double* cp = c.data<double>();
  for (int64_t bi = 0; bi < batch; ++bi) {
    const double* am = ap + bi * m * k;
    const double* bm = bp + (b.shape()[0] == 1 ? 0 : bi) * k * n;
    for (int64_t i = 0; i < m; ++i) {
      for (int64_t j = 0; j < n; ++j) {
        double acc = 0.0;
        for (int64_t q = 0; q < k; ++q) {
          const double av = p.trans_a ? am[q * m + i] : am[i * k + q];
          const double bv = p.trans_b ? bm[j * k + q] : bm[q * n + j];
          acc += av * bv;
        }
        cp[(bi * m + i) * n + j] = acc;
      }
    }
  }
}

}  // namespace cvd::reference
