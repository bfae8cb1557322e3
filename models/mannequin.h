// Mannequin Challenge hourglass depth network (Li et al. 2019, "Learning the Depths of Moving
// People by Watching Frozen People"; checkpoint best_depth_Ours_Bilinear_inc_3_net_G.pth), the
// network CVD fine-tunes by default. Layer table: docs/models.md section 4.
//
// Input contract: RGB in [0, 1] (no normalisation), [N, 3, H, W] with H and W multiples of 16.
// Output: log depth [N, 1, H, W] (depth = exp). The confidence head (sigmoid) is built so that
// state dicts load, but CVD does not use it.
// Parameter names follow the PyTorch state_dict ("seq.3.list.0.1.convs.2.3.weight").
// `width` scales every channel count; width * 16 must be a whole number (1, 0.5, 0.25, ...).
#pragma once
#include "models/depth_net.h"

namespace cvd {

class Sequential;
class Conv2d;

class MannequinNet : public DepthNet {
 public:
  MannequinNet(double width, Generator& gen);
  std::string arch() const override { return "mannequin"; }
  int alignment() const override { return 16; }
  DepthOutputKind output_kind() const override { return DepthOutputKind::log_depth; }
  Tensor normalize_input(const Tensor& rgb01) const override { return rgb01; }
  Tensor forward_raw(const Tensor& x) override;
  Tensor output_bias() override;
  Tensor output_weight() override;
  std::string type_name() const override { return "HourglassModel"; }
  // The forward returns (pred, confidence): pred_layer runs before uncertainty_layer.
  std::vector<std::string> execution_order() const override {
    return {"seq", "pred_layer", "uncertainty_layer"};
  }
  // The confidence map in (0, 1) (unused by CVD).
  Tensor confidence(const Tensor& x);

 private:
  std::shared_ptr<Sequential> seq_;
  std::shared_ptr<Conv2d> pred_;
  std::shared_ptr<Sequential> uncertainty_;
};

}  // namespace cvd
