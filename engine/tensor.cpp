#include "engine/tensor.h"

#include <cstring>
#include <sstream>

#include "engine/autograd.h"
#include "engine/dispatch.h"
#include "engine/kernel_params.h"
#include "engine/ops.h"
#include "engine/random.h"

namespace cvd {

int64_t shape_numel(const Shape& s) {
  int64_t n = 1;
  for (int64_t d : s) n *= d;
  return n;
}

Shape contiguous_strides(const Shape& s) {
  Shape st(s.size());
  int64_t acc = 1;
  for (int i = static_cast<int>(s.size()) - 1; i >= 0; --i) {
    st[i] = acc;
    acc *= s[i];
  }
  return st;
}

std::string shape_str(const Shape& s) {
  std::string r = "[";
  for (size_t i = 0; i < s.size(); ++i) r += (i ? ", " : "") + std::to_string(s[i]);
  return r + "]";
}

int wrap_dim(int d, int ndim) {
  int n = ndim == 0 ? 1 : ndim;
  CVD_CHECK(d >= -n && d < n, "dimension {} out of range for a {}-d tensor", d, ndim);
  return d < 0 ? d + n : d;
}

static void check_shape(const Shape& shape) {
  CVD_CHECK(shape.size() <= static_cast<size_t>(kMaxDims), "tensors have at most {} dims, got {}",
            kMaxDims, shape_str(shape));
  for (int64_t d : shape) CVD_CHECK(d >= 0, "negative size in shape {}", shape_str(shape));
}

Tensor Tensor::empty(const Shape& shape, DType dtype, DeviceId device) {
  check_shape(shape);
  if (!device.is_cpu()) kernel_registry();  // registers the device allocators
  Allocator* a = device_allocator(device);
  if (!a)
    fail(ErrorCategory::unsupported, "device {} is not available in this build or machine",
         device.str());
  auto impl = std::make_shared<TensorImpl>();
  impl->storage = std::make_shared<Storage>(shape_numel(shape) * dtype_size(dtype), a);
  impl->shape = shape;
  impl->strides = contiguous_strides(shape);
  impl->dtype = dtype;
  return Tensor(std::move(impl));
}

Tensor Tensor::zeros(const Shape& shape, DType dtype, DeviceId device) {
  return full(shape, 0.0, dtype, device);
}
Tensor Tensor::ones(const Shape& shape, DType dtype, DeviceId device) {
  return full(shape, 1.0, dtype, device);
}
Tensor Tensor::full(const Shape& shape, double value, DType dtype, DeviceId device) {
  Tensor t = empty(shape, dtype, device);
  t.fill_(value);
  return t;
}
Tensor Tensor::scalar(double value, DType dtype) { return full({}, value, dtype); }

template <class Src>
static Tensor from_values(const std::vector<Src>& values, const Shape& shape, DType dtype) {
  check_shape(shape);
  CVD_CHECK(static_cast<int64_t>(values.size()) == shape_numel(shape),
            "from_vector: {} values for shape {}", values.size(), shape_str(shape));
  Tensor t = Tensor::empty(shape, dtype);
  if (dtype == DType::f32) {
    float* p = t.data<float>();
    for (size_t i = 0; i < values.size(); ++i) p[i] = static_cast<float>(values[i]);
  } else {
    double* p = t.data<double>();
    for (size_t i = 0; i < values.size(); ++i) p[i] = static_cast<double>(values[i]);
  }
  return t;
}

Tensor Tensor::from_vector(const std::vector<double>& v, const Shape& s, DType dt) {
  return from_values(v, s, dt);
}
Tensor Tensor::from_vector(const std::vector<float>& v, const Shape& s, DType dt) {
  return from_values(v, s, dt);
}

Tensor Tensor::randn(const Shape& shape, Generator& gen, DType dtype, double std) {
  std::vector<double> v(shape_numel(shape));
  for (auto& x : v) x = gen.normal() * std;
  return from_vector(v, shape, dtype);
}

Tensor Tensor::uniform(const Shape& shape, Generator& gen, double lo, double hi, DType dtype) {
  std::vector<double> v(shape_numel(shape));
  for (auto& x : v) x = lo + (hi - lo) * gen.uniform();
  return from_vector(v, shape, dtype);
}

Tensor Tensor::from_storage(std::shared_ptr<Storage> storage, const Shape& shape, DType dtype,
                            int64_t offset) {
  check_shape(shape);
  CVD_CHECK(storage != nullptr, "from_storage: null storage");
  CVD_CHECK((offset + shape_numel(shape)) * static_cast<int64_t>(dtype_size(dtype)) <=
                static_cast<int64_t>(storage->nbytes()),
            "from_storage: shape {} at offset {} exceeds the storage of {} bytes", shape_str(shape),
            offset, storage->nbytes());
  auto impl = std::make_shared<TensorImpl>();
  impl->storage = std::move(storage);
  impl->shape = shape;
  impl->strides = contiguous_strides(shape);
  impl->offset = offset;
  impl->dtype = dtype;
  return Tensor(std::move(impl));
}

int64_t Tensor::size(int d) const { return shape()[wrap_dim(d, dim())]; }
int64_t Tensor::stride(int d) const { return strides()[wrap_dim(d, dim())]; }

bool Tensor::is_contiguous() const {
  int64_t expect = 1;
  const auto& s = shape();
  const auto& st = strides();
  for (int i = dim() - 1; i >= 0; --i) {
    if (s[i] == 1) continue;
    if (st[i] != expect) return false;
    expect *= s[i];
  }
  return true;
}

std::string Tensor::str() const {
  if (!defined()) return "undefined";
  return std::string(dtype_name(dtype())) + shape_str(shape()) + " " + device().str();
}

void* Tensor::data_ptr() const {
  const auto& st = impl()->storage;
  if (!st) return nullptr;
  return static_cast<char*>(st->data()) + impl()->offset * static_cast<int64_t>(element_size());
}

std::vector<double> Tensor::to_vector() const {
  Tensor t = detach();
  if (!t.device().is_cpu()) t = t.to(DeviceId::cpu());
  t = t.to(DType::f64).contiguous();
  const double* p = t.data<double>();
  return std::vector<double>(p, p + t.numel());
}

std::vector<float> Tensor::to_float_vector() const {
  std::vector<double> d = to_vector();
  return std::vector<float>(d.begin(), d.end());
}

double Tensor::item() const {
  CVD_CHECK(numel() == 1, "item() on a tensor of {} elements", numel());
  return to_vector()[0];
}

Tensor Tensor::contiguous() const { return cvd::contiguous(*this); }

Tensor Tensor::detach() const {
  auto impl = std::make_shared<TensorImpl>();
  impl->storage = impl_ ? impl_->storage : nullptr;
  impl->shape = shape();
  impl->strides = strides();
  impl->offset = offset();
  impl->dtype = dtype();
  return Tensor(std::move(impl));
}

void Tensor::copy_(const Tensor& src) const {
  CVD_CHECK(is_contiguous(), "copy_ into a non-contiguous tensor {}", str());
  CVD_CHECK(src.device() == device(), "copy_ across devices ({} -> {}): use to(DeviceId)",
            src.device().str(), device().str());
  Tensor s = src.detach().expand(shape());
  Tensor dst = detach();
  dispatch(OpId::copy, s, KernelArgs{{s}, {dst}, nullptr});
  bump_version();
}

void Tensor::fill_(double v) const {
  CVD_CHECK(is_contiguous(), "fill_ on a non-contiguous tensor {}", str());
  FillParams p{v};
  Tensor dst = detach();
  dispatch(OpId::fill, dst, KernelArgs{{}, {dst}, &p});
  bump_version();
}

Tensor& Tensor::requires_grad_(bool r) {
  CVD_CHECK(!r || is_leaf(), "requires_grad_ on a non-leaf tensor");
  impl()->requires_grad = r;
  return *this;
}

void Tensor::backward(const Tensor& g, bool retain_graph) const {
  run_backward(*this, g, retain_graph);
}

Tensor Tensor::reshape(const Shape& s) const { return cvd::reshape(*this, s); }
Tensor Tensor::permute(const std::vector<int>& d) const { return cvd::permute(*this, d); }
Tensor Tensor::transpose(int a, int b) const { return cvd::transpose(*this, a, b); }
Tensor Tensor::squeeze(int d) const { return cvd::squeeze(*this, d); }
Tensor Tensor::unsqueeze(int d) const { return cvd::unsqueeze(*this, d); }
Tensor Tensor::narrow(int d, int64_t s, int64_t l) const { return cvd::narrow(*this, d, s, l); }
Tensor Tensor::expand(const Shape& s) const { return cvd::expand(*this, s); }
Tensor Tensor::view(const Shape& s) const {
  CVD_CHECK(is_contiguous(), "view() of non-contiguous tensor {}; use reshape()", str());
  return cvd::reshape(*this, s);
}
Tensor Tensor::flatten(int start, int end) const {
  int n = dim();
  if (n == 0) return reshape({1});
  start = wrap_dim(start, n);
  end = wrap_dim(end, n);
  Shape s;
  for (int i = 0; i < start; ++i) s.push_back(size(i));
  int64_t m = 1;
  for (int i = start; i <= end; ++i) m *= size(i);
  s.push_back(m);
  for (int i = end + 1; i < n; ++i) s.push_back(size(i));
  return reshape(s);
}

Tensor operator+(const Tensor& a, const Tensor& b) { return add(a, b); }
Tensor operator-(const Tensor& a, const Tensor& b) { return sub(a, b); }
Tensor operator*(const Tensor& a, const Tensor& b) { return mul(a, b); }
Tensor operator/(const Tensor& a, const Tensor& b) { return div(a, b); }
Tensor operator+(const Tensor& a, double b) { return add_scalar(a, b); }
Tensor operator-(const Tensor& a, double b) { return add_scalar(a, -b); }
Tensor operator*(const Tensor& a, double b) { return mul_scalar(a, b); }
Tensor operator/(const Tensor& a, double b) { return mul_scalar(a, 1.0 / b); }
Tensor operator*(double a, const Tensor& b) { return mul_scalar(b, a); }
Tensor operator-(const Tensor& a) { return neg(a); }

}  // namespace cvd
