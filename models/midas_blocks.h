// Building blocks shared by the MiDaS networks (isl-org/MiDaS midas/blocks.py): the width rule,
// the ImageNet input normalisation, the residual conv units and the feature fusion blocks of the
// v2 decoder and of the v2.1 "custom" decoder. Names as the PyTorch modules.
#pragma once
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "engine/layers.h"

namespace cvd {

// Width multiplier of the MiDaS models: a power of two in (0, 1]; channel count c -> ceil(c * w),
// at least 1 (tools/reference/midas_models.py applies the same rule).
class MidasWidth {
 public:
  MidasWidth(double width, const char* arch);
  int64_t operator()(int64_t channels) const;
  double value() const { return width_; }

 private:
  double width_;
};

// A plain container of named children, like the empty nn.Module() that MiDaS uses as the
// namespaces "pretrained" and "scratch". It has no forward.
class ModuleGroup : public Module {
 public:
  template <class M>
  std::shared_ptr<M> add(const std::string& name, std::shared_ptr<M> m) {
    return register_module(name, std::move(m));
  }
  std::string type_name() const override { return "Module"; }
};

// (rgb01 - mean) / std with the ImageNet mean (0.485, 0.456, 0.406) and std (0.229, 0.224, 0.225).
Tensor imagenet_normalize(const Tensor& rgb01);

// Two 3x3 convs with bias ("conv1", "conv2"). The v2 unit applies its ReLU in place, so the skip
// carries relu(x): out = relu(x) + conv2(relu(conv1(relu(x)))). The v2.1 custom unit does not:
// out = x + conv2(relu(conv1(relu(x)))).
class ResidualConvUnit : public Module {
 public:
  enum class Skip { relu_of_input, input };
  ResidualConvUnit(int64_t features, Skip skip, Generator& gen);
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override {
    return skip_ == Skip::relu_of_input ? "ResidualConvUnit" : "ResidualConvUnit_custom";
  }

 private:
  std::shared_ptr<Conv2d> conv1_, conv2_;
  Skip skip_;
};

// MiDaS fusion block: o = x0 (+ resConfUnit1(skip)); o = resConfUnit2(o); o = 2x bilinear
// upsample with align_corners=True; the custom variant then applies a 1x1 conv ("out_conv",
// features -> out_features). A block without skip input (refinenet4) never uses resConfUnit1; it
// is built only when `with_skip_unit` (the released state dicts hold it, unused).
class FeatureFusionBlock : public Module {
 public:
  // v2: FeatureFusionBlock(features).
  FeatureFusionBlock(int64_t features, bool with_skip_unit, Generator& gen);
  // v2.1 custom: FeatureFusionBlock_custom(features, ReLU, bn=False) with a 1x1 out_conv.
  FeatureFusionBlock(int64_t features, int64_t out_features, bool with_skip_unit, Generator& gen);
  // Top of the decoder: no skip input.
  Tensor forward(const Tensor& x0) override;
  Tensor forward(const Tensor& x0, const Tensor& skip);
  // As forward, resizing to out_h x out_w instead of 2x (Depth Anything's DPT head: size=).
  Tensor forward_to(const Tensor& x0, int64_t out_h, int64_t out_w);
  Tensor forward_to(const Tensor& x0, const Tensor& skip, int64_t out_h, int64_t out_w);
  std::string type_name() const override {
    return out_conv_ ? "FeatureFusionBlock_custom" : "FeatureFusionBlock";
  }

 private:
  Tensor finish(const Tensor& o, int64_t out_h = 0, int64_t out_w = 0);  // 0: twice the size
  std::shared_ptr<Conv2d> out_conv_;
  std::shared_ptr<ResidualConvUnit> rcu1_, rcu2_;
};

// Module prefixes of a MiDaS network in the order its forward runs them (DepthNet::
// execution_order): encoder, then per level 4..1 layerN_rn, refinenetN (resConfUnit1,
// resConfUnit2, out_conv), then output_conv. Registration lists layer1_rn..layer4_rn first.
inline std::vector<std::string> midas_decoder_execution_order() {
  std::vector<std::string> order{"pretrained"};
  for (int i = 4; i >= 1; --i) {
    const std::string r = "scratch.refinenet" + std::to_string(i);
    order.insert(order.end(), {"scratch.layer" + std::to_string(i) + "_rn", r + ".resConfUnit1",
                               r + ".resConfUnit2", r + ".out_conv"});
  }
  order.push_back("scratch.output_conv");
  return order;
}

}  // namespace cvd
