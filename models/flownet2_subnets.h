// The four sub-networks of FlowNet2 (Ilg et al. 2017) as NVIDIA/flownet2-pytorch with
// batchNorm=False: FlowNetC, FlowNetS, FlowNetSD and FlowNetFusion. Layer table: docs/models.md section 5.
// Every conv has a bias and is followed by LeakyReLU(0.1) except predict_flow*, inter_conv*
// and upsampled_flow* (no activation). Parameter names follow the upstream state_dict
// ("conv1.0.weight", "deconv5.0.bias", "inter_conv5.0.weight", "predict_flow6.weight",
// "upsampled_flow6_to_5.weight").
//
// `width` scales every internal channel count c to max(1, floor(c * width + 0.5)); image inputs
// (3 / 6 / 11 / 12 channels), flows (2) and the 441 correlation channels stay fixed, so a tiny
// width is structurally identical to the published network.
#pragma once
#include <memory>

#include "engine/layers.h"
#include "engine/random.h"

namespace cvd {

// Channel count c at the given width multiplier (see above).
int64_t flownet_channels(int64_t c, double width);

// Shared by FlowNetC and FlowNetS: conv4 .. conv6_1 and the decoder (deconv5..2, predict_flow6..2,
// upsampled_flow6_to_5 .. 3_to_2), registered after conv3_1 as upstream. decode(c2, c3) returns
// flow2 [N, 2, H/4, W/4] (in units of 1/div_flow px).
class FlowNetEncoderDecoder : public Module {
 protected:
  FlowNetEncoderDecoder() = default;
  void build_tail(double width, bool upsample_bias, Generator& gen);
  Tensor decode(const Tensor& conv2_out, const Tensor& conv3_out);

  std::shared_ptr<Sequential> conv4_, conv4_1_, conv5_, conv5_1_, conv6_, conv6_1_;
  std::shared_ptr<Sequential> deconv5_, deconv4_, deconv3_, deconv2_;
  std::shared_ptr<Conv2d> predict_[5];             // predict_flow6 .. predict_flow2
  std::shared_ptr<ConvTranspose2d> upsampled_[4];  // 6_to_5 .. 3_to_2
};

// FlowNetS: x [N, input_channels, H, W] (12 in FlowNet2) -> flow2. Upsampling deconvs have no
// bias.
class FlowNetS : public FlowNetEncoderDecoder {
 public:
  FlowNetS(double width, Generator& gen, int64_t input_channels = 12);
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override { return "FlowNetS"; }

 private:
  std::shared_ptr<Sequential> conv1_, conv2_, conv3_, conv3_1_;
};

// FlowNetC: x [N, 6, H, W] (two 3-channel images) -> flow2. conv1-3 are shared by both images;
// Correlation(pad 20, kernel 1, max displacement 20, stride1 1, stride2 2) + LeakyReLU(0.1),
// concatenated after conv_redir(image 1).
class FlowNetC : public FlowNetEncoderDecoder {
 public:
  FlowNetC(double width, Generator& gen);
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override { return "FlowNetC"; }

 private:
  std::shared_ptr<Sequential> conv1_, conv2_, conv3_, conv_redir_, conv3_1_;
};

// FlowNetSD: x [N, 6, H, W] -> flow2, with inter_conv5..2 before each predict_flow.
class FlowNetSD : public Module {
 public:
  FlowNetSD(double width, Generator& gen);
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override { return "FlowNetSD"; }

 private:
  std::shared_ptr<Sequential> conv0_, conv1_, conv1_1_, conv2_, conv2_1_, conv3_, conv3_1_;
  std::shared_ptr<Sequential> conv4_, conv4_1_, conv5_, conv5_1_, conv6_, conv6_1_;
  std::shared_ptr<Sequential> deconv5_, deconv4_, deconv3_, deconv2_;
  std::shared_ptr<Sequential> inter_[4];           // inter_conv5 .. inter_conv2
  std::shared_ptr<Conv2d> predict_[5];             // predict_flow6 .. predict_flow2
  std::shared_ptr<ConvTranspose2d> upsampled_[4];  // 6_to_5 .. 3_to_2
};

// FlowNetFusion: x [N, 11, H, W] -> flow0 [N, 2, H, W] in pixels.
class FlowNetFusion : public Module {
 public:
  FlowNetFusion(double width, Generator& gen);
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override { return "FlowNetFusion"; }

 private:
  std::shared_ptr<Sequential> conv0_, conv1_, conv1_1_, conv2_, conv2_1_, deconv1_, deconv0_;
  std::shared_ptr<Sequential> inter_conv1_, inter_conv0_;
  std::shared_ptr<Conv2d> predict_flow2_, predict_flow1_, predict_flow0_;
  std::shared_ptr<ConvTranspose2d> upsampled_flow2_to_1_, upsampled_flow1_to_0_;
};

}  // namespace cvd
