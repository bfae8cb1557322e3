// Reductions: sum / mean over dims, and sum_to (the adjoint of broadcasting).
#include <algorithm>

#include "engine/op_support.h"

namespace cvd {

static std::vector<int> normalise_dims(std::vector<int> dims, int ndim) {
  if (dims.empty()) {
    for (int i = 0; i < ndim; ++i) dims.push_back(i);
    return dims;
  }
  for (int& d : dims) d = wrap_dim(d, ndim);
  std::sort(dims.begin(), dims.end());
  dims.erase(std::unique(dims.begin(), dims.end()), dims.end());
  if (ndim == 0) dims.clear();
  return dims;
}

Tensor sum(const Tensor& x_in, std::vector<int> dims_in, bool keepdim) {
  Tensor x = x_in.contiguous();
  std::vector<int> dims = normalise_dims(std::move(dims_in), x.dim());
  Shape out_shape, keep_shape = x.shape();
  for (int i = 0; i < x.dim(); ++i) {
    bool reduced = std::find(dims.begin(), dims.end(), i) != dims.end();
    if (reduced)
      keep_shape[i] = 1;
    else
      out_shape.push_back(x.size(i));
  }
  Tensor y = detail::empty_like_kind(out_shape, x);
  ReduceParams p{dims};
  dispatch(OpId::reduce_sum, x, KernelArgs{{x}, {y}, &p});
  Tensor yv = keepdim ? detail::make_view(y, keep_shape, contiguous_strides(keep_shape), 0) : y;
  if (!any_requires_grad({x})) return yv;
  return record("sum", yv, {x},
                [xshape = x.shape(), keep_shape](const Tensor& g, const std::vector<bool>&) {
                  return std::vector<Tensor>{g.reshape(keep_shape).expand(xshape)};
                });
}

Tensor mean(const Tensor& x, std::vector<int> dims_in, bool keepdim) {
  std::vector<int> dims = normalise_dims(dims_in, x.dim());
  int64_t n = 1;
  for (int d : dims) n *= x.size(d);
  return mul_scalar(sum(x, dims, keepdim), n > 0 ? 1.0 / static_cast<double>(n) : 0.0);
}

Tensor sum_to(const Tensor& x, const Shape& shape) {
  if (x.shape() == shape) return x;
  int lead = x.dim() - static_cast<int>(shape.size());
  CVD_CHECK(lead >= 0, "sum_to: cannot reduce {} to {}", shape_str(x.shape()), shape_str(shape));
  std::vector<int> dims;
  for (int i = 0; i < x.dim(); ++i) {
    if (i < lead) {
      dims.push_back(i);
    } else if (shape[i - lead] == 1 && x.size(i) != 1) {
      dims.push_back(i);
    } else {
      CVD_CHECK(shape[i - lead] == x.size(i), "sum_to: cannot reduce {} to {}",
                shape_str(x.shape()), shape_str(shape));
    }
  }
  if (dims.empty()) return x.reshape(shape);
  return sum(x, dims, true).reshape(shape);
}

}  // namespace cvd
