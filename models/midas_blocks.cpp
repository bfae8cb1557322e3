#include "models/midas_blocks.h"

#include <cmath>

#include "engine/ops.h"

namespace cvd {

MidasWidth::MidasWidth(double width, const char* arch) : width_(width) {
  const double k = std::round(-std::log2(width));
  CVD_CHECK(width > 0 && width <= 1 && std::abs(std::exp2(-k) - width) < 1e-12,
            "{}: width {} must be a power of two in (0, 1] (1, 0.5, 0.25, ...)", arch, width);
}

int64_t MidasWidth::operator()(int64_t channels) const {
  return std::max<int64_t>(1, static_cast<int64_t>(std::ceil(channels * width_ - 1e-9)));
}

Tensor imagenet_normalize(const Tensor& rgb01) {
  CVD_CHECK(rgb01.dim() == 4 && rgb01.size(1) == 3,
            "imagenet_normalize: input {} must be [N, 3, H, W] RGB", rgb01.str());
  const Tensor mean =
      Tensor::from_vector(std::vector<double>{0.485, 0.456, 0.406}, {1, 3, 1, 1}, rgb01.dtype())
          .to(rgb01.device());
  const Tensor inv_std = Tensor::from_vector(std::vector<double>{1 / 0.229, 1 / 0.224, 1 / 0.225},
                                             {1, 3, 1, 1}, rgb01.dtype())
                             .to(rgb01.device());
  return mul(sub(rgb01, mean), inv_std);
}

namespace {
Conv2dOptions conv3x3(int64_t c) { return Conv2dOptions(c, c, 3).with_padding(1); }
}  // namespace

ResidualConvUnit::ResidualConvUnit(int64_t features, Skip skip, Generator& gen) : skip_(skip) {
  conv1_ = register_module("conv1", std::make_shared<Conv2d>(conv3x3(features), gen));
  conv2_ = register_module("conv2", std::make_shared<Conv2d>(conv3x3(features), gen));
}

Tensor ResidualConvUnit::forward(const Tensor& x) {
  const Tensor rx = relu(x);
  const Tensor f = conv2_->forward(relu(conv1_->forward(rx)));
  return add(f, skip_ == Skip::relu_of_input ? rx : x);
}

FeatureFusionBlock::FeatureFusionBlock(int64_t features, bool with_skip_unit, Generator& gen) {
  const auto skip = ResidualConvUnit::Skip::relu_of_input;
  if (with_skip_unit) {
    rcu1_ =
        register_module("resConfUnit1", std::make_shared<ResidualConvUnit>(features, skip, gen));
  }
  rcu2_ = register_module("resConfUnit2", std::make_shared<ResidualConvUnit>(features, skip, gen));
}

FeatureFusionBlock::FeatureFusionBlock(int64_t features, int64_t out_features, bool with_skip_unit,
                                       Generator& gen) {
  const auto skip = ResidualConvUnit::Skip::input;
  out_conv_ = register_module(
      "out_conv", std::make_shared<Conv2d>(Conv2dOptions(features, out_features, 1), gen));
  if (with_skip_unit) {
    rcu1_ =
        register_module("resConfUnit1", std::make_shared<ResidualConvUnit>(features, skip, gen));
  }
  rcu2_ = register_module("resConfUnit2", std::make_shared<ResidualConvUnit>(features, skip, gen));
}

Tensor FeatureFusionBlock::forward(const Tensor& x0) { return finish(x0); }

Tensor FeatureFusionBlock::forward(const Tensor& x0, const Tensor& skip) {
  return forward_to(x0, skip, 0, 0);
}

Tensor FeatureFusionBlock::forward_to(const Tensor& x0, int64_t out_h, int64_t out_w) {
  return finish(x0, out_h, out_w);
}

Tensor FeatureFusionBlock::forward_to(const Tensor& x0, const Tensor& skip, int64_t out_h,
                                      int64_t out_w) {
  CVD_CHECK(rcu1_ != nullptr, "{}: built without resConfUnit1, cannot fuse a skip input",
            type_name());
  return finish(add(x0, rcu1_->forward(skip)), out_h, out_w);
}

Tensor FeatureFusionBlock::finish(const Tensor& o, int64_t out_h, int64_t out_w) {
  Tensor y = rcu2_->forward(o);
  if (out_h <= 0 || out_w <= 0) {
    out_h = y.size(2) * 2;
    out_w = y.size(3) * 2;
  }
  y = upsample_bilinear2d(y, out_h, out_w, /*align_corners=*/true);
  return out_conv_ ? out_conv_->forward(y) : y;
}

}  // namespace cvd
