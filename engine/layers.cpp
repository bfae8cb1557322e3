#include "engine/layers.h"

#include <fmt/format.h>

#include <cmath>

#include "engine/autograd.h"
#include "engine/ops.h"
#include "engine/process_group.h"
#include "engine/sync_batch_norm.h"

namespace cvd {

namespace {

// PyTorch's default for conv / linear: kaiming_uniform_(a = sqrt(5)) has bound
// gain * sqrt(3 / fan_in) with gain = sqrt(2 / (1 + 5)), i.e. 1 / sqrt(fan_in); the bias uses
// the same bound.
double default_init_bound(int64_t fan_in) {
  return fan_in > 0 ? 1.0 / std::sqrt(static_cast<double>(fan_in)) : 0.0;
}

Tensor uniform_init(const Shape& shape, double bound, Generator& gen, DType dtype) {
  return Tensor::uniform(shape, gen, -bound, bound, dtype);
}

std::string pair_str(int a, int b) { return fmt::format("({}, {})", a, b); }

void check_image_input(const Tensor& x, int64_t channels, const char* layer) {
  CVD_CHECK(x.dim() == 4, "{}: expected an input [N, C, H, W], got {}", layer, x.str());
  CVD_CHECK(x.size(1) == channels, "{}: expected {} input channels, got {}", layer, channels,
            x.str());
}

}  // namespace

// ---- Conv2d ------------------------------------------------------------------------------------

Conv2dParams Conv2dOptions::params() const {
  Conv2dParams p;
  p.stride_h = stride_h;
  p.stride_w = stride_w;
  p.pad_top = pad_top;
  p.pad_bottom = pad_bottom;
  p.pad_left = pad_left;
  p.pad_right = pad_right;
  p.dilation_h = dilation_h;
  p.dilation_w = dilation_w;
  p.groups = groups;
  return p;
}

Conv2d::Conv2d(const Conv2dOptions& o, Generator& gen, DType dtype) : options_(o) {
  CVD_CHECK(o.in_channels > 0 && o.out_channels > 0 && o.kernel_h > 0 && o.kernel_w > 0 &&
                o.groups > 0 && o.stride_h > 0 && o.stride_w > 0 && o.dilation_h > 0 &&
                o.dilation_w > 0 && o.pad_top >= 0 && o.pad_bottom >= 0 && o.pad_left >= 0 &&
                o.pad_right >= 0,
            "Conv2d: invalid options (in {}, out {}, kernel {}x{}, groups {})", o.in_channels,
            o.out_channels, o.kernel_h, o.kernel_w, o.groups);
  CVD_CHECK(o.in_channels % o.groups == 0 && o.out_channels % o.groups == 0,
            "Conv2d: channels {} -> {} not divisible by groups {}", o.in_channels, o.out_channels,
            o.groups);
  const int64_t fan_in = o.in_channels / o.groups * o.kernel_h * o.kernel_w;
  const double bound = default_init_bound(fan_in);
  weight = register_parameter(
      "weight", uniform_init({o.out_channels, o.in_channels / o.groups, o.kernel_h, o.kernel_w},
                             bound, gen, dtype));
  if (o.bias) bias = register_parameter("bias", uniform_init({o.out_channels}, bound, gen, dtype));
}

Tensor Conv2d::forward(const Tensor& x) {
  check_image_input(x, options_.in_channels, "Conv2d");
  return conv2d(x, weight, bias, options_.params());
}

std::string Conv2d::extra_repr() const {
  const auto& o = options_;
  std::string s = fmt::format("{}, {}, kernel_size={}, stride={}", o.in_channels, o.out_channels,
                              pair_str(o.kernel_h, o.kernel_w), pair_str(o.stride_h, o.stride_w));
  if (o.pad_top || o.pad_bottom || o.pad_left || o.pad_right) {
    if (o.pad_top == o.pad_bottom && o.pad_left == o.pad_right) {
      s += ", padding=" + pair_str(o.pad_top, o.pad_left);
    } else {
      s += fmt::format(", padding=(top {}, bottom {}, left {}, right {})", o.pad_top, o.pad_bottom,
                       o.pad_left, o.pad_right);
    }
  }
  if (o.dilation_h != 1 || o.dilation_w != 1) {
    s += ", dilation=" + pair_str(o.dilation_h, o.dilation_w);
  }
  if (o.groups != 1) s += fmt::format(", groups={}", o.groups);
  if (!o.bias) s += ", bias=False";
  return s;
}

// ---- ConvTranspose2d ---------------------------------------------------------------------------

ConvTranspose2dParams ConvTranspose2dOptions::params() const {
  ConvTranspose2dParams p;
  p.stride_h = stride_h;
  p.stride_w = stride_w;
  p.pad_top = pad_top;
  p.pad_bottom = pad_bottom;
  p.pad_left = pad_left;
  p.pad_right = pad_right;
  p.output_padding_h = output_padding_h;
  p.output_padding_w = output_padding_w;
  p.dilation_h = dilation_h;
  p.dilation_w = dilation_w;
  p.groups = groups;
  return p;
}

ConvTranspose2d::ConvTranspose2d(const ConvTranspose2dOptions& o, Generator& gen, DType dtype)
    : options_(o) {
  CVD_CHECK(o.in_channels > 0 && o.out_channels > 0 && o.kernel_h > 0 && o.kernel_w > 0 &&
                o.groups > 0 && o.stride_h > 0 && o.stride_w > 0 && o.dilation_h > 0 &&
                o.dilation_w > 0,
            "ConvTranspose2d: invalid options (in {}, out {}, kernel {}x{}, groups {})",
            o.in_channels, o.out_channels, o.kernel_h, o.kernel_w, o.groups);
  CVD_CHECK(o.in_channels % o.groups == 0 && o.out_channels % o.groups == 0,
            "ConvTranspose2d: channels {} -> {} not divisible by groups {}", o.in_channels,
            o.out_channels, o.groups);
  CVD_CHECK(o.output_padding_h >= 0 && o.output_padding_w >= 0 &&
                (o.output_padding_h < o.stride_h || o.output_padding_h < o.dilation_h) &&
                (o.output_padding_w < o.stride_w || o.output_padding_w < o.dilation_w),
            "ConvTranspose2d: output_padding ({}, {}) must be smaller than stride or dilation",
            o.output_padding_h, o.output_padding_w);
  // PyTorch computes fan_in from weight.size(1) = out / groups.
  const int64_t fan_in = o.out_channels / o.groups * o.kernel_h * o.kernel_w;
  const double bound = default_init_bound(fan_in);
  weight = register_parameter(
      "weight", uniform_init({o.in_channels, o.out_channels / o.groups, o.kernel_h, o.kernel_w},
                             bound, gen, dtype));
  if (o.bias) bias = register_parameter("bias", uniform_init({o.out_channels}, bound, gen, dtype));
}

Tensor ConvTranspose2d::forward(const Tensor& x) {
  check_image_input(x, options_.in_channels, "ConvTranspose2d");
  return conv_transpose2d(x, weight, bias, options_.params());
}

std::string ConvTranspose2d::extra_repr() const {
  const auto& o = options_;
  std::string s = fmt::format("{}, {}, kernel_size={}, stride={}", o.in_channels, o.out_channels,
                              pair_str(o.kernel_h, o.kernel_w), pair_str(o.stride_h, o.stride_w));
  if (o.pad_top || o.pad_bottom || o.pad_left || o.pad_right) {
    s += fmt::format(", padding=(top {}, bottom {}, left {}, right {})", o.pad_top, o.pad_bottom,
                     o.pad_left, o.pad_right);
  }
  if (o.output_padding_h || o.output_padding_w) {
    s += ", output_padding=" + pair_str(o.output_padding_h, o.output_padding_w);
  }
  if (o.groups != 1) s += fmt::format(", groups={}", o.groups);
  if (!o.bias) s += ", bias=False";
  return s;
}

// ---- BatchNorm2d -------------------------------------------------------------------------------

BatchNorm2d::BatchNorm2d(const BatchNorm2dOptions& o, DType dtype) : options_(o) {
  CVD_CHECK(o.num_features > 0 && o.eps > 0, "BatchNorm2d: invalid options (features {}, eps {})",
            o.num_features, o.eps);
  CVD_CHECK(!o.momentum || (*o.momentum >= 0 && *o.momentum <= 1),
            "BatchNorm2d: momentum {} outside [0, 1]", *o.momentum);
  const Shape c{o.num_features};
  if (o.affine) {
    weight = register_parameter("weight", Tensor::ones(c, dtype));
    bias = register_parameter("bias", Tensor::zeros(c, dtype));
  }
  if (o.track_running_stats) {
    running_mean = register_buffer("running_mean", Tensor::zeros(c, dtype));
    running_var = register_buffer("running_var", Tensor::ones(c, dtype));
    num_batches_tracked =
        register_buffer("num_batches_tracked", Tensor::zeros({}, DType::f64), false);
  }
}

Tensor BatchNorm2d::forward(const Tensor& x) { return forward_impl(x, nullptr); }

Tensor BatchNorm2d::forward_act(const Tensor& x, const UnaryParams& act) {
  return forward_impl(x, &act);
}

Tensor BatchNorm2d::forward_impl(const Tensor& x, const UnaryParams* act) {
  check_image_input(x, options_.num_features, "BatchNorm2d");
  const bool batch_stats = is_training() || !options_.track_running_stats;
  CVD_CHECK(!batch_stats || x.numel() / x.size(1) > 1,
            "BatchNorm2d: expected more than 1 value per channel when training, got input {}",
            x.str());
  BatchNormParams p;
  p.training = batch_stats;
  p.eps = options_.eps;
  Tensor rm = running_mean, rv = running_var;
  p.momentum = 0.0;
  if (!options_.track_running_stats) {
    // Batch statistics only: the op's running-stat update goes to throwaway tensors.
    rm = Tensor::zeros({options_.num_features}, x.dtype(), x.device());
    rv = Tensor::ones({options_.num_features}, x.dtype(), x.device());
  } else if (is_training()) {
    const double n = num_batches_tracked.item() + 1.0;
    num_batches_tracked.fill_(n);
    p.momentum = options_.momentum ? *options_.momentum : 1.0 / n;
  }
  if (batch_stats && sync_batch_norm_active()) {
    Tensor y = sync_batch_norm(x, rm, rv, weight, bias, p);
    return act ? unary(y, *act) : y;
  }
  return act ? batch_norm_act(x, rm, rv, weight, bias, p, *act)
             : batch_norm(x, rm, rv, weight, bias, p);
}

std::string BatchNorm2d::extra_repr() const {
  const auto& o = options_;
  return fmt::format("{}, eps={}, momentum={}, affine={}, track_running_stats={}", o.num_features,
                     o.eps, o.momentum ? fmt::format("{}", *o.momentum) : "None",
                     o.affine ? "True" : "False", o.track_running_stats ? "True" : "False");
}

// ---- Linear ------------------------------------------------------------------------------------

Linear::Linear(int64_t in_features, int64_t out_features, Generator& gen, bool with_bias,
               DType dtype)
    : in_features_(in_features), out_features_(out_features) {
  CVD_CHECK(in_features > 0 && out_features > 0, "Linear: invalid sizes {} -> {}", in_features,
            out_features);
  const double bound = default_init_bound(in_features);
  weight =
      register_parameter("weight", uniform_init({out_features, in_features}, bound, gen, dtype));
  if (with_bias) bias = register_parameter("bias", uniform_init({out_features}, bound, gen, dtype));
}

Tensor Linear::forward(const Tensor& x) {
  CVD_CHECK(x.dim() >= 1 && x.size(-1) == in_features_, "Linear: expected [..., {}], got {}",
            in_features_, x.str());
  return linear(x, weight, bias);
}

std::string Linear::extra_repr() const {
  return fmt::format("in_features={}, out_features={}, bias={}", in_features_, out_features_,
                     bias.defined() ? "True" : "False");
}

LayerNorm::LayerNorm(int64_t normalized_shape, double eps, bool elementwise_affine, DType dtype)
    : c_(normalized_shape), eps_(eps) {
  CVD_CHECK(normalized_shape > 0 && eps >= 0, "LayerNorm: invalid size {} or eps {}",
            normalized_shape, eps);
  if (elementwise_affine) {
    weight = register_parameter("weight", Tensor::full({normalized_shape}, 1.0, dtype));
    bias = register_parameter("bias", Tensor::full({normalized_shape}, 0.0, dtype));
  }
}

Tensor LayerNorm::forward(const Tensor& x) {
  CVD_CHECK(x.dim() >= 1 && x.size(-1) == c_, "LayerNorm: expected [..., {}], got {}", c_, x.str());
  return layer_norm(x, weight, bias, eps_);
}

std::string LayerNorm::extra_repr() const {
  return fmt::format("({},), eps={}, elementwise_affine={}", c_, eps_,
                     weight.defined() ? "True" : "False");
}

// ---- Activations -------------------------------------------------------------------------------

Tensor GELU::forward(const Tensor& x) { return gelu(x); }
Tensor ReLU::forward(const Tensor& x) { return relu(x); }
Tensor ReLU6::forward(const Tensor& x) { return relu6(x); }
Tensor LeakyReLU::forward(const Tensor& x) { return leaky_relu(x, negative_slope_); }
std::string LeakyReLU::extra_repr() const {
  return fmt::format("negative_slope={}", negative_slope_);
}
Tensor Sigmoid::forward(const Tensor& x) { return sigmoid(x); }
Tensor Tanh::forward(const Tensor& x) { return tanh(x); }
Tensor MaxPool2d::forward(const Tensor& x) { return max_pool2d(x, params_); }
Tensor AvgPool2d::forward(const Tensor& x) { return avg_pool2d(x, params_); }

// ---- Sequential --------------------------------------------------------------------------------

Sequential::Sequential(std::initializer_list<std::shared_ptr<Module>> modules) {
  for (const auto& m : modules) push_back(m);
}

const std::shared_ptr<Module>& Sequential::operator[](size_t i) const {
  CVD_CHECK(i < children().size(), "Sequential: index {} out of range (size {})", i,
            children().size());
  return children()[i].second;
}

Tensor Sequential::forward(const Tensor& x) {
  Tensor y = x;
  const auto& ch = children();
  for (size_t i = 0; i < ch.size(); ++i) {
    // BatchNorm2d then ReLU / ReLU6: one batch_norm_act, whose output need not be kept for
    // backward (engine/rematerialize.h). Same values and gradients as the two modules.
    if (auto* bn = dynamic_cast<BatchNorm2d*>(ch[i].second.get()); bn && i + 1 < ch.size()) {
      const Module* next = ch[i + 1].second.get();
      if (dynamic_cast<const ReLU*>(next)) {
        y = bn->forward_act(y, {UnaryOp::relu});
        ++i;
        continue;
      }
      if (dynamic_cast<const ReLU6*>(next)) {
        y = bn->forward_act(y, {UnaryOp::clip, 0.0, 6.0});
        ++i;
        continue;
      }
    }
    y = ch[i].second->forward(y);
  }
  return y;
}

}  // namespace cvd
