// Depth Anything V2 (DepthAnything/Depth-Anything-V2, depth_anything_v2/dpt.py): a DINOv2 ViT
// encoder (models/vit_encoder.h) and the DPT head, predicting relative inverse depth (affine-
// invariant disparity, >= 0). Layer table: docs/models.md.
//
// DPT head: the final-normed patch tokens of four blocks ([2, 5, 8, 11] for ViT-S / B) as
// [N, C, ph, pw] maps; per level a 1x1 projection to out_channels[i], then 4x / 2x transposed
// convs, identity, a 3x3 stride-2 conv; 3x3 convs (no bias) to `features` ("layerN_rn"); fusion
// blocks refinenet4..1 as MiDaS v2.1's custom ones, each resizing (bilinear, align_corners) to the
// next level's size and refinenet1 by 2x; output_conv1 3x3 to features / 2, a bilinear resize to
// the input size (ph * 14 x pw * 14), output_conv2 = 3x3 to 32, ReLU, 1x1 to 1, ReLU; and a final
// ReLU. refinenet4.resConfUnit1 is in the released state dicts and built here (so the parameter
// count is the reference's) but never used by the forward.
//
// Input contract: RGB in [0, 1], [N, 3, H, W], H and W multiples of 14 (native 518 on the short
// side); normalize_input applies the ImageNet mean / std.
#pragma once
#include <array>
#include <string>

#include "models/depth_net.h"
#include "models/vit_encoder.h"

namespace cvd {

struct DepthAnythingConfig {
  // The architecture-table row this configuration is (models/depth_net_architectures.cpp): the
  // name `arch()` reports and .cvdw files carry.
  std::string arch = "depth_anything_v2";
  VitConfig vit;
  int64_t features = 64;
  std::array<int64_t, 4> out_channels{48, 96, 192, 384};
  std::array<int, 4> layers{2, 5, 8, 11};  // blocks whose tokens the head reads

  static DepthAnythingConfig vits();  // "depth_anything_v2": 24.8 M parameters (Apache-2.0)
  static DepthAnythingConfig vitb();  // "depth_anything_v2_vitb": 97.5 M
  static DepthAnythingConfig vitl();  // "depth_anything_v2_vitl": 335.3 M
  // `base` with every width (embedding, features, out_channels) times `width`, a power of two in
  // (0, 1]; the embedding stays a multiple of the base's heads. width 1 = base.
  static DepthAnythingConfig scaled(DepthAnythingConfig base, double width);
  static DepthAnythingConfig vits_scaled(double width) { return scaled(vits(), width); }
};

class DepthAnythingV2Net : public DepthNet {
 public:
  DepthAnythingV2Net(const DepthAnythingConfig& config, Generator& gen);
  ~DepthAnythingV2Net() override;
  std::string arch() const override { return config_.arch; }
  int alignment() const override { return config_.vit.patch; }
  DepthOutputKind output_kind() const override { return DepthOutputKind::inverse_depth; }
  Tensor normalize_input(const Tensor& rgb01) const override;
  Tensor forward_raw(const Tensor& x) override;
  Tensor output_bias() override;
  Tensor output_weight() override;
  std::vector<std::string> execution_order() const override;
  std::vector<std::string> unused_in_forward() const override {
    return {"pretrained.mask_token", "depth_head.scratch.refinenet4.resConfUnit1"};
  }
  std::string type_name() const override { return "DepthAnythingV2"; }
  const DepthAnythingConfig& config() const { return config_; }

 private:
  struct Parts;
  DepthAnythingConfig config_;
  std::unique_ptr<Parts> parts_;
};

}  // namespace cvd
