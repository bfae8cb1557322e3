// Standard layers built on engine/ops.h, with PyTorch's parameter names, shapes, defaults and
// initialisation (so state dicts convert 1:1 and a seeded model is reproducible):
//   Conv2d / ConvTranspose2d / Linear: weight ~ kaiming_uniform(a = sqrt(5)) = U(-1/sqrt(fan_in),
//   1/sqrt(fan_in)), bias ~ U(-1/sqrt(fan_in), 1/sqrt(fan_in)); weight drawn first, then bias.
//   BatchNorm2d: weight 1, bias 0, running_mean 0, running_var 1, num_batches_tracked 0.
#pragma once
#include <cstdint>
#include <initializer_list>
#include <memory>
#include <optional>
#include <string>

#include "engine/kernel_params.h"
#include "engine/module.h"
#include "engine/random.h"

namespace cvd {

// ---- Convolutions ------------------------------------------------------------------------------

// Conv2dOptions(in, out, kernel).with_stride(2).with_padding(1).with_bias(false) ...
struct Conv2dOptions {
  Conv2dOptions(int64_t in, int64_t out, int kernel) : Conv2dOptions(in, out, kernel, kernel) {}
  Conv2dOptions(int64_t in, int64_t out, int kh, int kw)
      : in_channels(in), out_channels(out), kernel_h(kh), kernel_w(kw) {}
  Conv2dOptions& with_stride(int s) { return with_stride(s, s); }
  Conv2dOptions& with_stride(int sh, int sw) {
    stride_h = sh;
    stride_w = sw;
    return *this;
  }
  Conv2dOptions& with_padding(int p) { return with_padding(p, p, p, p); }
  Conv2dOptions& with_padding(int ph, int pw) { return with_padding(ph, ph, pw, pw); }
  Conv2dOptions& with_padding(int top, int bottom, int left, int right) {
    pad_top = top;
    pad_bottom = bottom;
    pad_left = left;
    pad_right = right;
    return *this;
  }
  Conv2dOptions& with_dilation(int d) { return with_dilation(d, d); }
  Conv2dOptions& with_dilation(int dh, int dw) {
    dilation_h = dh;
    dilation_w = dw;
    return *this;
  }
  Conv2dOptions& with_groups(int g) {
    groups = g;
    return *this;
  }
  Conv2dOptions& with_bias(bool b) {
    bias = b;
    return *this;
  }
  Conv2dParams params() const;

  int64_t in_channels, out_channels;
  int kernel_h, kernel_w;
  int stride_h = 1, stride_w = 1;
  int pad_top = 0, pad_bottom = 0, pad_left = 0, pad_right = 0;
  int dilation_h = 1, dilation_w = 1;
  int groups = 1;
  bool bias = true;
};

class Conv2d : public Module {
 public:
  Conv2d(const Conv2dOptions& options, Generator& gen, DType dtype = DType::f32);
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override { return "Conv2d"; }
  std::string extra_repr() const override;
  const Conv2dOptions& options() const { return options_; }

  Tensor weight;  // [out, in / groups, kh, kw]
  Tensor bias;    // [out], undefined without bias

 private:
  Conv2dOptions options_;
};

// Padding p removes p rows / columns on each side of the full output (PyTorch semantics);
// output_padding adds to the bottom / right.
struct ConvTranspose2dOptions {
  ConvTranspose2dOptions(int64_t in, int64_t out, int kernel)
      : ConvTranspose2dOptions(in, out, kernel, kernel) {}
  ConvTranspose2dOptions(int64_t in, int64_t out, int kh, int kw)
      : in_channels(in), out_channels(out), kernel_h(kh), kernel_w(kw) {}
  ConvTranspose2dOptions& with_stride(int s) { return with_stride(s, s); }
  ConvTranspose2dOptions& with_stride(int sh, int sw) {
    stride_h = sh;
    stride_w = sw;
    return *this;
  }
  ConvTranspose2dOptions& with_padding(int p) { return with_padding(p, p, p, p); }
  ConvTranspose2dOptions& with_padding(int ph, int pw) { return with_padding(ph, ph, pw, pw); }
  ConvTranspose2dOptions& with_padding(int top, int bottom, int left, int right) {
    pad_top = top;
    pad_bottom = bottom;
    pad_left = left;
    pad_right = right;
    return *this;
  }
  ConvTranspose2dOptions& with_output_padding(int p) { return with_output_padding(p, p); }
  ConvTranspose2dOptions& with_output_padding(int ph, int pw) {
    output_padding_h = ph;
    output_padding_w = pw;
    return *this;
  }
  ConvTranspose2dOptions& with_dilation(int d) {
    dilation_h = dilation_w = d;
    return *this;
  }
  ConvTranspose2dOptions& with_groups(int g) {
    groups = g;
    return *this;
  }
  ConvTranspose2dOptions& with_bias(bool b) {
    bias = b;
    return *this;
  }
  ConvTranspose2dParams params() const;

  int64_t in_channels, out_channels;
  int kernel_h, kernel_w;
  int stride_h = 1, stride_w = 1;
  int pad_top = 0, pad_bottom = 0, pad_left = 0, pad_right = 0;
  int output_padding_h = 0, output_padding_w = 0;
  int dilation_h = 1, dilation_w = 1;
  int groups = 1;
  bool bias = true;
};

class ConvTranspose2d : public Module {
 public:
  ConvTranspose2d(const ConvTranspose2dOptions& options, Generator& gen, DType dtype = DType::f32);
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override { return "ConvTranspose2d"; }
  std::string extra_repr() const override;
  const ConvTranspose2dOptions& options() const { return options_; }

  Tensor weight;  // [in, out / groups, kh, kw]
  Tensor bias;    // [out], undefined without bias

 private:
  ConvTranspose2dOptions options_;
};

// ---- Normalisation -----------------------------------------------------------------------------

struct BatchNorm2dOptions {
  explicit BatchNorm2dOptions(int64_t features) : num_features(features) {}
  BatchNorm2dOptions& with_eps(double e) {
    eps = e;
    return *this;
  }
  // nullopt = cumulative moving average (PyTorch momentum=None).
  BatchNorm2dOptions& with_momentum(std::optional<double> m) {
    momentum = m;
    return *this;
  }
  BatchNorm2dOptions& with_affine(bool a) {
    affine = a;
    return *this;
  }
  BatchNorm2dOptions& with_track_running_stats(bool t) {
    track_running_stats = t;
    return *this;
  }

  int64_t num_features;
  double eps = 1e-5;
  std::optional<double> momentum = 0.1;
  bool affine = true;
  bool track_running_stats = true;
};

// Training: normalises with the batch statistics, updates running_mean / running_var (unbiased
// variance) with `momentum` and counts num_batches_tracked. Eval: uses the running statistics.
// Without track_running_stats it always uses batch statistics and has no buffers.
class BatchNorm2d : public Module {
 public:
  explicit BatchNorm2d(const BatchNorm2dOptions& options, DType dtype = DType::f32);
  Tensor forward(const Tensor& x) override;
  // act(forward(x)) for act = relu or clip (relu6) as one op (engine/ops.h batch_norm_act).
  Tensor forward_act(const Tensor& x, const UnaryParams& act);
  std::string type_name() const override { return "BatchNorm2d"; }
  std::string extra_repr() const override;
  const BatchNorm2dOptions& options() const { return options_; }

  Tensor weight, bias;               // [C] gamma / beta; undefined without affine
  Tensor running_mean, running_var;  // [C]; undefined without track_running_stats
  Tensor num_batches_tracked;        // 0-d f64 counter (keeps f64 through to(DType))

 private:
  Tensor forward_impl(const Tensor& x, const UnaryParams* act);
  BatchNorm2dOptions options_;
};

// ---- Linear -------------------------------------------------------------------------------------

class Linear : public Module {
 public:
  Linear(int64_t in_features, int64_t out_features, Generator& gen, bool bias = true,
         DType dtype = DType::f32);
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override { return "Linear"; }
  std::string extra_repr() const override;

  Tensor weight;  // [out, in]
  Tensor bias;    // [out], undefined without bias

 private:
  int64_t in_features_, out_features_;
};

// LayerNorm(C, eps) over the last dimension: weight 1, bias 0 (without elementwise_affine: none).
class LayerNorm : public Module {
 public:
  LayerNorm(int64_t normalized_shape, double eps = 1e-5, bool elementwise_affine = true,
            DType dtype = DType::f32);
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override { return "LayerNorm"; }
  std::string extra_repr() const override;
  double eps() const { return eps_; }

  Tensor weight, bias;  // [C]; undefined without elementwise_affine

 private:
  int64_t c_;
  double eps_;
};

// ---- Activations and parameter-free layers ------------------------------------------------------

// GELU, erf form (PyTorch nn.GELU()).
class GELU : public Module {
 public:
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override { return "GELU"; }
};

class ReLU : public Module {
 public:
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override { return "ReLU"; }
};

class ReLU6 : public Module {
 public:
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override { return "ReLU6"; }
};

class LeakyReLU : public Module {
 public:
  explicit LeakyReLU(double negative_slope = 0.01) : negative_slope_(negative_slope) {}
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override { return "LeakyReLU"; }
  std::string extra_repr() const override;

 private:
  double negative_slope_;
};

class Sigmoid : public Module {
 public:
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override { return "Sigmoid"; }
};

class Tanh : public Module {
 public:
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override { return "Tanh"; }
};

class Identity : public Module {
 public:
  Tensor forward(const Tensor& x) override { return x; }
  std::string type_name() const override { return "Identity"; }
};

class MaxPool2d : public Module {
 public:
  explicit MaxPool2d(const Pool2dParams& params) : params_(params) {}
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override { return "MaxPool2d"; }

 private:
  Pool2dParams params_;
};

class AvgPool2d : public Module {
 public:
  explicit AvgPool2d(const Pool2dParams& params) : params_(params) {}
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override { return "AvgPool2d"; }

 private:
  Pool2dParams params_;
};

// ---- Containers --------------------------------------------------------------------------------

// Children named "0", "1", ... in order; forward chains them.
class Sequential : public Module {
 public:
  Sequential() = default;
  Sequential(std::initializer_list<std::shared_ptr<Module>> modules);
  // Appends `m` under the next index name and returns it.
  template <class M>
  std::shared_ptr<M> push_back(std::shared_ptr<M> m) {
    return register_module(std::to_string(children().size()), std::move(m));
  }
  size_t size() const { return children().size(); }
  const std::shared_ptr<Module>& operator[](size_t i) const;
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override { return "Sequential"; }
};

}  // namespace cvd
