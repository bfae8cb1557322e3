// Shape and layout ops: views (reshape, permute, squeeze, narrow, expand), copies (contiguous,
// clone, dtype/device conversion), concat and pad.
#include <numeric>

#include "engine/backend_info.h"
#include "engine/op_support.h"

namespace cvd {

namespace detail {
Tensor make_view(const Tensor& x, const Shape& shape, const Shape& strides, int64_t offset) {
  auto impl = std::make_shared<TensorImpl>();
  impl->storage = x.storage();
  impl->shape = shape;
  impl->strides = strides;
  impl->offset = offset;
  impl->dtype = x.dtype();
  return Tensor(std::move(impl));
}
}  // namespace detail

using detail::make_view;

Tensor reshape(const Tensor& x_in, const Shape& shape_in) {
  Shape shape = shape_in;
  int64_t known = 1;
  int infer = -1;
  for (size_t i = 0; i < shape.size(); ++i) {
    if (shape[i] == -1) {
      CVD_CHECK(infer < 0, "reshape: more than one -1 in {}", shape_str(shape_in));
      infer = static_cast<int>(i);
    } else {
      known *= shape[i];
    }
  }
  if (infer >= 0) {
    CVD_CHECK(known > 0 && x_in.numel() % known == 0, "reshape: cannot infer -1 in {} from {}",
              shape_str(shape_in), shape_str(x_in.shape()));
    shape[infer] = x_in.numel() / known;
  }
  CVD_CHECK(shape_numel(shape) == x_in.numel(), "reshape: {} has {} elements, {} has {}",
            shape_str(x_in.shape()), x_in.numel(), shape_str(shape), shape_numel(shape));
  if (shape == x_in.shape()) return x_in;
  Tensor x = x_in.contiguous();
  Tensor y = make_view(x, shape, contiguous_strides(shape), x.offset());
  if (!any_requires_grad({x})) return y;
  return record("reshape", y, {x}, [xs = x.shape()](const Tensor& g, const std::vector<bool>&) {
    return std::vector<Tensor>{g.reshape(xs)};
  });
}

Tensor permute(const Tensor& x, const std::vector<int>& dims_in) {
  int n = x.dim();
  CVD_CHECK(static_cast<int>(dims_in.size()) == n, "permute: {} dims for a {}-d tensor",
            dims_in.size(), n);
  std::vector<int> dims(n), inv(n, -1);
  Shape shape(n), strides(n);
  for (int i = 0; i < n; ++i) {
    dims[i] = wrap_dim(dims_in[i], n);
    CVD_CHECK(inv[dims[i]] < 0, "permute: repeated dim {}", dims[i]);
    inv[dims[i]] = i;
    shape[i] = x.size(dims[i]);
    strides[i] = x.stride(dims[i]);
  }
  Tensor y = make_view(x, shape, strides, x.offset());
  if (!any_requires_grad({x})) return y;
  return record("permute", y, {x}, [inv](const Tensor& g, const std::vector<bool>&) {
    return std::vector<Tensor>{permute(g, inv)};
  });
}

Tensor transpose(const Tensor& x, int a, int b) {
  std::vector<int> d(x.dim());
  std::iota(d.begin(), d.end(), 0);
  std::swap(d[wrap_dim(a, x.dim())], d[wrap_dim(b, x.dim())]);
  return permute(x, d);
}

Tensor squeeze(const Tensor& x, int dim) {
  int d = wrap_dim(dim, x.dim());
  if (x.dim() == 0 || x.size(d) != 1) return x;
  Shape s = x.shape();
  s.erase(s.begin() + d);
  return reshape(x, s);
}

Tensor unsqueeze(const Tensor& x, int dim) {
  int d = wrap_dim(dim, x.dim() + 1);
  Shape s = x.shape();
  s.insert(s.begin() + d, 1);
  return reshape(x, s);
}

Tensor narrow(const Tensor& x, int dim, int64_t start, int64_t length) {
  int d = wrap_dim(dim, x.dim());
  CVD_CHECK(start >= 0 && length >= 0 && start + length <= x.size(d),
            "narrow: [{}, {}) out of range for dim {} of size {}", start, start + length, d,
            x.size(d));
  if (start == 0 && length == x.size(d)) return x;
  Shape s = x.shape();
  s[d] = length;
  Tensor y = make_view(x, s, x.strides(), x.offset() + start * x.stride(d));
  if (!any_requires_grad({x})) return y;
  return record(
      "narrow", y, {x},
      [d, start, length, full = x.size(d), n = x.dim()](const Tensor& g, const std::vector<bool>&) {
        std::vector<int64_t> pads(2 * n, 0);
        int k = n - 1 - d;  // F.pad order: last dim first
        pads[2 * k] = start;
        pads[2 * k + 1] = full - start - length;
        return std::vector<Tensor>{pad(g, pads, 0.0)};
      });
}

Tensor expand(const Tensor& x, const Shape& shape) {
  if (x.shape() == shape) return x;
  int lead = static_cast<int>(shape.size()) - x.dim();
  CVD_CHECK(lead >= 0, "expand: cannot expand {} to {}", shape_str(x.shape()), shape_str(shape));
  Shape strides(shape.size());
  for (size_t i = 0; i < shape.size(); ++i) {
    int j = static_cast<int>(i) - lead;
    if (j < 0) {
      strides[i] = 0;
    } else if (x.size(j) == shape[i]) {
      strides[i] = x.stride(j);
    } else {
      CVD_CHECK(x.size(j) == 1, "expand: cannot expand {} to {}", shape_str(x.shape()),
                shape_str(shape));
      strides[i] = 0;
    }
  }
  Tensor y = make_view(x, shape, strides, x.offset());
  if (!any_requires_grad({x})) return y;
  return record("expand", y, {x}, [xs = x.shape()](const Tensor& g, const std::vector<bool>&) {
    return std::vector<Tensor>{sum_to(g, xs)};
  });
}

static Tensor copy_to_new(const Tensor& x, DType dt) {
  Tensor y = Tensor::empty(x.shape(), dt, x.device());
  Tensor xs = x.detach();
  dispatch(OpId::copy, xs, KernelArgs{{xs}, {y}, nullptr});
  return y;
}

Tensor contiguous(const Tensor& x) {
  if (x.is_contiguous()) return x;
  Tensor y = copy_to_new(x, x.dtype());
  if (!any_requires_grad({x})) return y;
  return record("contiguous", y, {x},
                [](const Tensor& g, const std::vector<bool>&) { return std::vector<Tensor>{g}; });
}

Tensor Tensor::clone() const {
  Tensor y = copy_to_new(*this, dtype());
  if (!any_requires_grad({*this})) return y;
  return record("clone", y, {*this},
                [](const Tensor& g, const std::vector<bool>&) { return std::vector<Tensor>{g}; });
}

Tensor Tensor::to(DType t) const {
  if (t == dtype()) return *this;
  Tensor y = copy_to_new(*this, t);
  if (!any_requires_grad({*this})) return y;
  return record("to_dtype", y, {*this}, [src = dtype()](const Tensor& g, const std::vector<bool>&) {
    return std::vector<Tensor>{g.to(src)};
  });
}

// Cross-device copies go through the device backend's hook (engine/backend_registry.h).

Tensor Tensor::to(DeviceId d) const {
  if (d == device()) return *this;
  Tensor y = device_copy(contiguous(), d);
  if (!any_requires_grad({*this})) return y;
  return record("to_device", y, {*this},
                [src = device()](const Tensor& g, const std::vector<bool>&) {
                  return std::vector<Tensor>{g.to(src)};
                });
}

Tensor concat(const std::vector<Tensor>& xs_in, int dim) {
  CVD_CHECK(!xs_in.empty(), "concat of an empty list");
  int n = xs_in[0].dim();
  int d = wrap_dim(dim, n);
  std::vector<Tensor> xs;
  Shape out = xs_in[0].shape();
  out[d] = 0;
  for (const auto& t : xs_in) {
    detail::check_same_kind("concat", xs_in[0], t);
    CVD_CHECK(t.dim() == n, "concat: {} vs {}", xs_in[0].str(), t.str());
    for (int i = 0; i < n; ++i)
      CVD_CHECK(i == d || t.size(i) == xs_in[0].size(i), "concat along {}: {} vs {}", d,
                xs_in[0].str(), t.str());
    out[d] += t.size(d);
    xs.push_back(t.contiguous());
  }
  Tensor y = detail::empty_like_kind(out, xs[0]);
  ConcatParams p{d};
  dispatch(OpId::concat, xs[0], KernelArgs{xs, {y}, &p});
  if (!any_requires_grad(xs)) return y;
  std::vector<int64_t> sizes;
  for (auto& t : xs) sizes.push_back(t.size(d));
  return record("concat", y, xs, [d, sizes](const Tensor& g, const std::vector<bool>& need) {
    std::vector<Tensor> r(sizes.size());
    int64_t off = 0;
    for (size_t i = 0; i < sizes.size(); ++i) {
      if (need[i]) r[i] = narrow(g, d, off, sizes[i]);
      off += sizes[i];
    }
    return r;
  });
}

Tensor pad(const Tensor& x_in, const std::vector<int64_t>& pads, double value) {
  int n = x_in.dim();
  CVD_CHECK(pads.size() % 2 == 0 && static_cast<int>(pads.size()) <= 2 * n,
            "pad: {} amounts for a {}-d tensor", pads.size(), n);
  Tensor x = x_in;
  PadParams p;
  p.before.assign(n, 0);
  p.after.assign(n, 0);
  p.value = value;
  bool any_positive = false;
  for (size_t k = 0; k < pads.size() / 2; ++k) {
    int d = n - 1 - static_cast<int>(k);
    int64_t b = pads[2 * k], a = pads[2 * k + 1];
    // Negative amounts crop first.
    int64_t crop_b = b < 0 ? -b : 0, crop_a = a < 0 ? -a : 0;
    if (crop_b || crop_a) x = narrow(x, d, crop_b, x.size(d) - crop_b - crop_a);
    p.before[d] = std::max<int64_t>(b, 0);
    p.after[d] = std::max<int64_t>(a, 0);
    any_positive |= p.before[d] > 0 || p.after[d] > 0;
  }
  if (!any_positive) return x;
  x = x.contiguous();
  Shape out = x.shape();
  for (int d = 0; d < n; ++d) out[d] += p.before[d] + p.after[d];
  Tensor y = detail::empty_like_kind(out, x);
  dispatch(OpId::pad, x, KernelArgs{{x}, {y}, &p});
  if (!any_requires_grad({x})) return y;
  return record("pad", y, {x}, [p, xs = x.shape()](const Tensor& g, const std::vector<bool>&) {
    Tensor r = g;
    for (size_t d = 0; d < xs.size(); ++d) r = narrow(r, static_cast<int>(d), p.before[d], xs[d]);
    return std::vector<Tensor>{r};
  });
}

}  // namespace cvd
