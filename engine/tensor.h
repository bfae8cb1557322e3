// Tensor: a strided view of refcounted storage, with the autograd metadata of define-by-run
// reverse-mode differentiation. A Tensor is a cheap handle (a shared pointer); copies alias.
#pragma once
#include <cstdint>
#include <initializer_list>
#include <memory>
#include <string>
#include <vector>

#include "engine/dtype.h"
#include "engine/error.h"
#include "engine/storage.h"

namespace cvd {

using Shape = std::vector<int64_t>;
inline constexpr int kMaxDims = 6;

int64_t shape_numel(const Shape& s);
Shape contiguous_strides(const Shape& s);
std::string shape_str(const Shape& s);

struct Node;
struct Rematerializer;
class Generator;

struct TensorImpl {
  std::shared_ptr<Storage> storage;
  Shape shape;
  Shape strides;       // in elements
  int64_t offset = 0;  // in elements
  DType dtype = DType::f32;
  bool requires_grad = false;
  std::shared_ptr<TensorImpl> grad;  // accumulated gradient (leaves)
  std::shared_ptr<Node> grad_fn;     // the node that produced this tensor (non-leaves)
  // Set by ops whose output backward may regenerate instead of keeping (engine/rematerialize.h).
  std::shared_ptr<const Rematerializer> rematerializer;
};

class Tensor {
 public:
  Tensor() = default;
  explicit Tensor(std::shared_ptr<TensorImpl> impl) : impl_(std::move(impl)) {}

  // ---- Factories ------------------------------------------------------------------------------
  static Tensor empty(const Shape& shape, DType dtype = DType::f32,
                      DeviceId device = DeviceId::cpu());
  static Tensor zeros(const Shape& shape, DType dtype = DType::f32,
                      DeviceId device = DeviceId::cpu());
  static Tensor ones(const Shape& shape, DType dtype = DType::f32,
                     DeviceId device = DeviceId::cpu());
  static Tensor full(const Shape& shape, double value, DType dtype = DType::f32,
                     DeviceId device = DeviceId::cpu());
  static Tensor scalar(double value, DType dtype = DType::f32);
  // Copies `values` (row-major) into a new CPU tensor of `shape` converted to `dtype`.
  static Tensor from_vector(const std::vector<double>& values, const Shape& shape,
                            DType dtype = DType::f32);
  static Tensor from_vector(const std::vector<float>& values, const Shape& shape,
                            DType dtype = DType::f32);
  // Normal(0, std) / Uniform[lo, hi) samples from `gen`, generated in f64 then converted, so the
  // same seed gives the same values in f32 and f64.
  static Tensor randn(const Shape& shape, Generator& gen, DType dtype = DType::f32,
                      double std = 1.0);
  static Tensor uniform(const Shape& shape, Generator& gen, double lo, double hi,
                        DType dtype = DType::f32);
  // Wraps existing storage.
  static Tensor from_storage(std::shared_ptr<Storage> storage, const Shape& shape, DType dtype,
                             int64_t offset = 0);

  // ---- Metadata -------------------------------------------------------------------------------
  bool defined() const { return impl_ != nullptr; }
  const Shape& shape() const { return impl()->shape; }
  const Shape& strides() const { return impl()->strides; }
  int dim() const { return static_cast<int>(impl()->shape.size()); }
  int64_t size(int d) const;  // negative d counts from the end
  int64_t stride(int d) const;
  int64_t numel() const { return shape_numel(impl()->shape); }
  int64_t offset() const { return impl()->offset; }
  DType dtype() const { return impl()->dtype; }
  DeviceId device() const { return impl()->storage ? impl()->storage->device() : DeviceId::cpu(); }
  size_t element_size() const { return dtype_size(dtype()); }
  size_t nbytes() const { return static_cast<size_t>(numel()) * element_size(); }
  bool is_contiguous() const;
  const std::shared_ptr<Storage>& storage() const { return impl()->storage; }
  uint64_t version() const { return impl()->storage ? impl()->storage->version() : 0; }
  void bump_version() const {
    if (impl()->storage) impl()->storage->bump_version();
  }
  std::string str() const;  // "f32[2, 3] cpu"
  TensorImpl* impl() const {
    CVD_CHECK(impl_ != nullptr, "use of an undefined tensor");
    return impl_.get();
  }
  const std::shared_ptr<TensorImpl>& impl_ptr() const { return impl_; }
  bool same(const Tensor& o) const { return impl_ == o.impl_; }

  // ---- Data access (CPU) ----------------------------------------------------------------------
  void* data_ptr() const;  // address of element 0 (storage + offset)
  template <class T>
  T* data() const {
    CVD_CHECK(dtype() == dtype_of<T>::value, "tensor {} accessed as the wrong dtype", str());
    return static_cast<T*>(data_ptr());
  }
  double item() const;                    // the one element, as double (any device)
  std::vector<double> to_vector() const;  // all elements, row-major, as double (any device)
  std::vector<float> to_float_vector() const;

  // ---- Conversions and copies (not recorded by autograd unless stated) ------------------------
  Tensor contiguous() const;    // recorded; returns *this when already contiguous
  Tensor clone() const;         // recorded; always copies
  Tensor to(DType t) const;     // recorded
  Tensor to(DeviceId d) const;  // recorded
  Tensor detach() const;        // shares storage, no autograd history
  // In-place: copies src (broadcast to this shape, any dtype) into this tensor's elements.
  void copy_(const Tensor& src) const;
  void fill_(double v) const;
  void zero_() const { fill_(0.0); }

  // ---- Autograd -------------------------------------------------------------------------------
  bool requires_grad() const { return impl()->requires_grad; }
  Tensor& requires_grad_(bool r = true);
  bool is_leaf() const { return impl()->grad_fn == nullptr; }
  const std::shared_ptr<Node>& grad_fn() const { return impl()->grad_fn; }
  Tensor grad() const { return Tensor(impl()->grad); }
  void set_grad(const Tensor& g) const { impl()->grad = g.impl_; }
  void zero_grad() const { impl()->grad.reset(); }
  // Reverse-mode differentiation from this tensor. Without an argument it must be a scalar
  // (numel 1) and the seed is 1. The graph is freed afterwards unless retain_graph.
  void backward(const Tensor& grad = Tensor(), bool retain_graph = false) const;

  // ---- Views and shape ops (recorded; see engine/ops.h) ----------------------------------------
  Tensor reshape(const Shape& s) const;
  Tensor view(const Shape& s) const;  // requires compatible strides
  Tensor permute(const std::vector<int>& dims) const;
  Tensor transpose(int a, int b) const;
  Tensor squeeze(int d) const;
  Tensor unsqueeze(int d) const;
  Tensor narrow(int d, int64_t start, int64_t length) const;
  Tensor expand(const Shape& s) const;
  Tensor flatten(int start = 0, int end = -1) const;

 private:
  std::shared_ptr<TensorImpl> impl_;
};

// Arithmetic operators (recorded; broadcasting).
Tensor operator+(const Tensor& a, const Tensor& b);
Tensor operator-(const Tensor& a, const Tensor& b);
Tensor operator*(const Tensor& a, const Tensor& b);
Tensor operator/(const Tensor& a, const Tensor& b);
Tensor operator+(const Tensor& a, double b);
Tensor operator-(const Tensor& a, double b);
Tensor operator*(const Tensor& a, double b);
Tensor operator/(const Tensor& a, double b);
Tensor operator*(double a, const Tensor& b);
Tensor operator-(const Tensor& a);

// Normalises a possibly negative dimension index against `ndim`, with a clear error.
int wrap_dim(int d, int ndim);

}  // namespace cvd
