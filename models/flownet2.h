// FlowNet2 (Ilg et al. 2017) as NVIDIA/flownet2-pytorch's models.FlowNet2 (batchNorm=False,
// div_flow 20, rgb_max 255): FlowNetC -> FlowNetS -> FlowNetS, FlowNetSD in parallel, fused by
// FlowNetFusion. 162,518,834 parameters at width 1. The chain (docs/models.md section 5):
//   x = (images - per-pair per-channel mean over both frames) / 255;
//   C(x) -> bilinear x4 (align_corners=False) of flow2 * 20 = f1; S1(refine(f1)) -> likewise f2;
//   S2(refine(f2)) -> nearest x4 of flow2 * 20 = f3; SD(x) -> nearest x4 of flow2 / 20 = f4
//   (the division is upstream's, deliberately kept);
//   refine(f) = cat[x, w, f / 20, ChannelNorm(x0 - w)] with w = Resample2d(x1, f) (12 ch);
//   Fusion(cat[x0, f4, f3, CN(f4), CN(f3), CN(x0 - Resample2d(x1, f4)), CN(x0 - Resample2d(x1,
//   f3))]) (11 ch) = the flow in pixels at full resolution.
// Children flownetc, flownets_1, flownets_2, flownets_d, flownetfusion, so parameter names are
// upstream's state_dict names ("flownetc.conv1.0.weight").
#pragma once
#include <memory>

#include "models/flownet2_subnets.h"

namespace cvd {

// The raw flow2 outputs of the sub-networks inside one FlowNet2 forward, [N, 2, H/4, W/4].
struct FlowNet2Trace {
  Tensor flownetc, flownets_1, flownets_2, flownets_d;
};

class FlowNet2 : public Module {
 public:
  static constexpr int kAlignment = 64;     // H and W must be multiples of this
  static constexpr double kDivFlow = 20.0;  // flow scale of the sub-networks
  static constexpr double kRgbMax = 255.0;

  // Seeded random weights (PyTorch's default layer init); load real ones with load_weights.
  FlowNet2(double width, Generator& gen);
  double width() const { return width_; }
  std::string type_name() const override { return "FlowNet2"; }
  std::string extra_repr() const override;

  // img0, img1: RGB in [0, 255], [N, 3, H, W], H and W multiples of 64. Returns the flow from
  // img0 to img1 in pixels, [N, 2, H, W]: pixel (x, y) of img0 is at (x + u, y + v) in img1.
  Tensor forward_pair(const Tensor& img0, const Tensor& img1, FlowNet2Trace* trace = nullptr);

  // The pieces of the chain (public for tests).
  // [N, 6, H, W]: both images minus their per-sample per-channel mean over both frames, / 255.
  static Tensor normalize_pair(const Tensor& img0, const Tensor& img1);
  // flownet2's Resample2d: img [N, C, H, W] sampled bilinearly at (x + u, y + v) of flow
  // [N, 2, H, W], indices clamped to the image (= grid_sample bilinear, border, align_corners).
  static Tensor resample2d(const Tensor& img, const Tensor& flow);
  // The 12-channel input of FlowNetS given x [N, 6, H, W] and a full-resolution flow in pixels.
  static Tensor refinement_input(const Tensor& x, const Tensor& flow);
  // The 11-channel input of FlowNetFusion given x and the full-resolution flows of FlowNetSD
  // (f4) and FlowNetS 2 (f3).
  static Tensor fusion_input(const Tensor& x, const Tensor& sd_flow, const Tensor& s2_flow);

  FlowNetC& flownetc() { return *flownetc_; }
  FlowNetS& flownets_1() { return *flownets_1_; }
  FlowNetS& flownets_2() { return *flownets_2_; }
  FlowNetSD& flownets_d() { return *flownets_d_; }
  FlowNetFusion& flownetfusion() { return *flownetfusion_; }

 private:
  double width_;
  std::shared_ptr<FlowNetC> flownetc_;
  std::shared_ptr<FlowNetS> flownets_1_, flownets_2_;
  std::shared_ptr<FlowNetSD> flownets_d_;
  std::shared_ptr<FlowNetFusion> flownetfusion_;
};

}  // namespace cvd
