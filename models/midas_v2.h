// MiDaS v2 (Ranftl et al. 2020): MidasNet(features=256, non_negative=True) with a ResNeXt-101
// 32x8d encoder and the RefineNet-style fusion decoder. Layer table: docs/models.md section 2.
//
// Input contract: RGB in [0, 1], [N, 3, H, W] with H and W multiples of 32; normalize_input
// applies the ImageNet mean / std. Output: non-negative relative inverse depth [N, 1, H, W].
// Parameter names follow the released state dict ("pretrained.layer3.12.conv2.weight",
// "scratch.refinenet2.resConfUnit1.conv1.bias", ...). The released file also holds
// scratch.refinenet4.resConfUnit1.* which the forward never uses: this model does not have it,
// load with load_depth_net_state (models/midas_state.h) or drop those names.
//
// Width multiplier (tests): `width` must be a power of two in (0, 1]; every channel count c
// becomes ceil(c * width) (at least 1) and the ResNeXt cardinality is min(32, ceil(256 * width)),
// which divides every bottleneck width. The same rule is in tools/reference/midas_models.py.
#pragma once
#include "models/depth_net.h"
#include "models/midas_blocks.h"

namespace cvd {

class Sequential;

class MidasV2Net : public DepthNet {
 public:
  MidasV2Net(double width, Generator& gen);
  ~MidasV2Net() override;
  std::string arch() const override { return "midas_v2"; }
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
  std::string type_name() const override { return "MidasNet"; }

 private:
  struct Parts;
  std::unique_ptr<Parts> parts_;
};

}  // namespace cvd
