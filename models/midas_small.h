// MiDaS v2.1 small: MidasNet_small(features=64, backbone="efficientnet_lite3", expand=True) with
// the tf_efficientnet_lite3 encoder (gen-efficientnet: ReLU6, no squeeze-excite, BN eps 1e-3,
// TF "SAME" padding) and the custom fusion decoder. Layer table: docs/models.md section 3.
//
// Input contract: RGB in [0, 1], [N, 3, H, W] with H and W multiples of 32 (native long side
// 256); normalize_input applies the ImageNet mean / std. Output: non-negative relative inverse
// depth [N, 1, H, W].
// Names follow the released state dict: pretrained.layer1 = Sequential(conv_stem, bn1, act1,
// blocks[0], blocks[1]) ("pretrained.layer1.3.0.conv_dw.weight", "pretrained.layer1.4.2.bn3.bias"),
// layer2 = blocks[2:3], layer3 = blocks[3:5], layer4 = blocks[5:7]; scratch.* as MiDaS. The unused
// scratch.refinenet4.resConfUnit1 of the released file is not built (see depth_net_state.h).
//
// TF "SAME" padding is static here: stride-1 convs pad (k - 1) / 2 on each side; the stride-2
// convs pad k - 2 in total, the smaller half at the top / left (k3s2: 0 / 1, k5s2: 1 / 2). That
// equals TF's dynamic rule because every stride-2 conv sees an even size (H, W % 32 == 0).
//
// Width multiplier (tests): a power of two in (0, 1]; channel counts c -> ceil(c * width), the
// expanded width of an inverted-residual block is 6 x its (scaled) input width, and residual
// connections are those of the full network (every block of a stage but the first).
// The same rule is in tools/reference/midas_models.py.
#pragma once
#include "models/depth_net.h"
#include "models/midas_blocks.h"

namespace cvd {

class MidasSmallNet : public DepthNet {
 public:
  MidasSmallNet(double width, Generator& gen);
  ~MidasSmallNet() override;
  std::string arch() const override { return "midas_small"; }
  int alignment() const override { return 32; }
  DepthOutputKind output_kind() const override { return DepthOutputKind::inverse_depth; }
  Tensor normalize_input(const Tensor& rgb01) const override;
  Tensor forward_raw(const Tensor& x) override;
  Tensor output_bias() override;
  Tensor output_weight() override;
  // See midas_decoder_execution_order (models/midas_blocks.h).
  std::vector<std::string> execution_order() const override {
    return midas_decoder_execution_order();
  }
  std::string type_name() const override { return "MidasNet_small"; }

 private:
  struct Parts;
  std::unique_ptr<Parts> parts_;
};

}  // namespace cvd
