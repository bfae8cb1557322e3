#include "models/flownet2_subnets.h"

#include <cmath>
#include <string>

#include "engine/error.h"
#include "engine/ops.h"

namespace cvd {

int64_t flownet_channels(int64_t c, double width) {
  CVD_CHECK(width > 0 && width <= 1, "flownet2: width {} must be in (0, 1]", width);
  return std::max<int64_t>(1,
                           static_cast<int64_t>(std::floor(static_cast<double>(c) * width + 0.5)));
}

namespace {

constexpr double kLeakySlope = 0.1;
constexpr int kCorrelationChannels = 441;  // (2 * 20 / 2 + 1)^2

// conv(batchNorm=False, in, out, k, s): Sequential(Conv2d(pad (k-1)/2, bias), LeakyReLU(0.1)).
std::shared_ptr<Sequential> conv(int64_t in, int64_t out, int k, int s, Generator& gen) {
  auto seq = std::make_shared<Sequential>();
  seq->push_back(std::make_shared<Conv2d>(
      Conv2dOptions(in, out, k).with_stride(s).with_padding((k - 1) / 2), gen));
  seq->push_back(std::make_shared<LeakyReLU>(kLeakySlope));
  return seq;
}

// i_conv(batchNorm=False, in, out): Sequential(Conv2d 3x3 pad 1, bias), no activation.
std::shared_ptr<Sequential> i_conv(int64_t in, int64_t out, Generator& gen) {
  auto seq = std::make_shared<Sequential>();
  seq->push_back(std::make_shared<Conv2d>(Conv2dOptions(in, out, 3).with_padding(1), gen));
  return seq;
}

// deconv(in, out): Sequential(ConvTranspose2d k4 s2 p1 with bias, LeakyReLU(0.1)).
std::shared_ptr<Sequential> deconv(int64_t in, int64_t out, Generator& gen) {
  auto seq = std::make_shared<Sequential>();
  seq->push_back(std::make_shared<ConvTranspose2d>(
      ConvTranspose2dOptions(in, out, 4).with_stride(2).with_padding(1), gen));
  seq->push_back(std::make_shared<LeakyReLU>(kLeakySlope));
  return seq;
}

std::shared_ptr<Conv2d> predict_flow(int64_t in, Generator& gen) {
  return std::make_shared<Conv2d>(Conv2dOptions(in, 2, 3).with_padding(1), gen);
}

std::shared_ptr<ConvTranspose2d> upsample_flow(bool bias, Generator& gen) {
  return std::make_shared<ConvTranspose2d>(
      ConvTranspose2dOptions(2, 2, 4).with_stride(2).with_padding(1).with_bias(bias), gen);
}

const char* const kPredictNames[5] = {"predict_flow6", "predict_flow5", "predict_flow4",
                                      "predict_flow3", "predict_flow2"};
const char* const kUpsampleNames[4] = {"upsampled_flow6_to_5", "upsampled_flow5_to_4",
                                       "upsampled_flow4_to_3", "upsampled_flow3_to_2"};

}  // namespace

// ---- FlowNetC / FlowNetS shared tail -----------------------------------------------------------

void FlowNetEncoderDecoder::build_tail(double width, bool upsample_bias, Generator& gen) {
  auto s = [width](int64_t c) { return flownet_channels(c, width); };
  conv4_ = register_module("conv4", conv(s(256), s(512), 3, 2, gen));
  conv4_1_ = register_module("conv4_1", conv(s(512), s(512), 3, 1, gen));
  conv5_ = register_module("conv5", conv(s(512), s(512), 3, 2, gen));
  conv5_1_ = register_module("conv5_1", conv(s(512), s(512), 3, 1, gen));
  conv6_ = register_module("conv6", conv(s(512), s(1024), 3, 2, gen));
  conv6_1_ = register_module("conv6_1", conv(s(1024), s(1024), 3, 1, gen));
  const int64_t cat5 = 2 * s(512) + 2, cat4 = s(512) + s(256) + 2, cat3 = s(256) + s(128) + 2,
                cat2 = s(128) + s(64) + 2;
  deconv5_ = register_module("deconv5", deconv(s(1024), s(512), gen));
  deconv4_ = register_module("deconv4", deconv(cat5, s(256), gen));
  deconv3_ = register_module("deconv3", deconv(cat4, s(128), gen));
  deconv2_ = register_module("deconv2", deconv(cat3, s(64), gen));
  const int64_t predict_in[5] = {s(1024), cat5, cat4, cat3, cat2};
  for (int i = 0; i < 5; ++i)
    predict_[i] = register_module(kPredictNames[i], predict_flow(predict_in[i], gen));
  for (int i = 0; i < 4; ++i)
    upsampled_[i] = register_module(kUpsampleNames[i], upsample_flow(upsample_bias, gen));
}

Tensor FlowNetEncoderDecoder::decode(const Tensor& c2, const Tensor& c3) {
  Tensor c4 = conv4_1_->forward(conv4_->forward(c3));
  Tensor c5 = conv5_1_->forward(conv5_->forward(c4));
  Tensor c6 = conv6_1_->forward(conv6_->forward(c5));
  Tensor flow6 = predict_[0]->forward(c6);
  Tensor cat5 = concat({c5, deconv5_->forward(c6), upsampled_[0]->forward(flow6)}, 1);
  Tensor flow5 = predict_[1]->forward(cat5);
  Tensor cat4 = concat({c4, deconv4_->forward(cat5), upsampled_[1]->forward(flow5)}, 1);
  Tensor flow4 = predict_[2]->forward(cat4);
  Tensor cat3 = concat({c3, deconv3_->forward(cat4), upsampled_[2]->forward(flow4)}, 1);
  Tensor flow3 = predict_[3]->forward(cat3);
  Tensor cat2 = concat({c2, deconv2_->forward(cat3), upsampled_[3]->forward(flow3)}, 1);
  return predict_[4]->forward(cat2);
}

// ---- FlowNetS ----------------------------------------------------------------------------------

FlowNetS::FlowNetS(double width, Generator& gen, int64_t input_channels) {
  auto s = [width](int64_t c) { return flownet_channels(c, width); };
  conv1_ = register_module("conv1", conv(input_channels, s(64), 7, 2, gen));
  conv2_ = register_module("conv2", conv(s(64), s(128), 5, 2, gen));
  conv3_ = register_module("conv3", conv(s(128), s(256), 5, 2, gen));
  conv3_1_ = register_module("conv3_1", conv(s(256), s(256), 3, 1, gen));
  build_tail(width, /*upsample_bias=*/false, gen);
}

Tensor FlowNetS::forward(const Tensor& x) {
  Tensor c2 = conv2_->forward(conv1_->forward(x));
  Tensor c3 = conv3_1_->forward(conv3_->forward(c2));
  return decode(c2, c3);
}

// ---- FlowNetC ----------------------------------------------------------------------------------

FlowNetC::FlowNetC(double width, Generator& gen) {
  auto s = [width](int64_t c) { return flownet_channels(c, width); };
  conv1_ = register_module("conv1", conv(3, s(64), 7, 2, gen));
  conv2_ = register_module("conv2", conv(s(64), s(128), 5, 2, gen));
  conv3_ = register_module("conv3", conv(s(128), s(256), 5, 2, gen));
  conv_redir_ = register_module("conv_redir", conv(s(256), s(32), 1, 1, gen));
  conv3_1_ = register_module("conv3_1", conv(s(32) + kCorrelationChannels, s(256), 3, 1, gen));
  build_tail(width, /*upsample_bias=*/true, gen);
}

Tensor FlowNetC::forward(const Tensor& x) {
  CVD_CHECK(x.dim() == 4 && x.size(1) == 6, "FlowNetC: input {} must be [N, 6, H, W]", x.str());
  Tensor c2a = conv2_->forward(conv1_->forward(narrow(x, 1, 0, 3)));
  Tensor c3a = conv3_->forward(c2a);
  Tensor c3b = conv3_->forward(conv2_->forward(conv1_->forward(narrow(x, 1, 3, 3))));
  CorrelationParams corr;
  corr.pad = 20;
  corr.kernel_size = 1;
  corr.max_displacement = 20;
  corr.stride1 = 1;
  corr.stride2 = 2;
  Tensor c = leaky_relu(correlation(c3a, c3b, corr), kLeakySlope);
  Tensor c3 = conv3_1_->forward(concat({conv_redir_->forward(c3a), c}, 1));
  return decode(c2a, c3);
}

// ---- FlowNetSD ---------------------------------------------------------------------------------

FlowNetSD::FlowNetSD(double width, Generator& gen) {
  auto s = [width](int64_t c) { return flownet_channels(c, width); };
  conv0_ = register_module("conv0", conv(6, s(64), 3, 1, gen));
  conv1_ = register_module("conv1", conv(s(64), s(64), 3, 2, gen));
  conv1_1_ = register_module("conv1_1", conv(s(64), s(128), 3, 1, gen));
  conv2_ = register_module("conv2", conv(s(128), s(128), 3, 2, gen));
  conv2_1_ = register_module("conv2_1", conv(s(128), s(128), 3, 1, gen));
  conv3_ = register_module("conv3", conv(s(128), s(256), 3, 2, gen));
  conv3_1_ = register_module("conv3_1", conv(s(256), s(256), 3, 1, gen));
  conv4_ = register_module("conv4", conv(s(256), s(512), 3, 2, gen));
  conv4_1_ = register_module("conv4_1", conv(s(512), s(512), 3, 1, gen));
  conv5_ = register_module("conv5", conv(s(512), s(512), 3, 2, gen));
  conv5_1_ = register_module("conv5_1", conv(s(512), s(512), 3, 1, gen));
  conv6_ = register_module("conv6", conv(s(512), s(1024), 3, 2, gen));
  conv6_1_ = register_module("conv6_1", conv(s(1024), s(1024), 3, 1, gen));
  const int64_t cat5 = 2 * s(512) + 2, cat4 = s(512) + s(256) + 2, cat3 = s(256) + s(128) + 2,
                cat2 = s(128) + s(64) + 2;
  deconv5_ = register_module("deconv5", deconv(s(1024), s(512), gen));
  deconv4_ = register_module("deconv4", deconv(cat5, s(256), gen));
  deconv3_ = register_module("deconv3", deconv(cat4, s(128), gen));
  deconv2_ = register_module("deconv2", deconv(cat3, s(64), gen));
  const int64_t inter_in[4] = {cat5, cat4, cat3, cat2};
  const int64_t inter_out[4] = {s(512), s(256), s(128), s(64)};
  for (int i = 0; i < 4; ++i)
    inter_[i] = register_module("inter_conv" + std::to_string(5 - i),
                                i_conv(inter_in[i], inter_out[i], gen));
  const int64_t predict_in[5] = {s(1024), s(512), s(256), s(128), s(64)};
  for (int i = 0; i < 5; ++i)
    predict_[i] = register_module(kPredictNames[i], predict_flow(predict_in[i], gen));
  for (int i = 0; i < 4; ++i)
    upsampled_[i] = register_module(kUpsampleNames[i], upsample_flow(true, gen));
}

Tensor FlowNetSD::forward(const Tensor& x) {
  Tensor c1 = conv1_1_->forward(conv1_->forward(conv0_->forward(x)));
  Tensor c2 = conv2_1_->forward(conv2_->forward(c1));
  Tensor c3 = conv3_1_->forward(conv3_->forward(c2));
  Tensor c4 = conv4_1_->forward(conv4_->forward(c3));
  Tensor c5 = conv5_1_->forward(conv5_->forward(c4));
  Tensor c6 = conv6_1_->forward(conv6_->forward(c5));
  Tensor flow6 = predict_[0]->forward(c6);
  Tensor cat5 = concat({c5, deconv5_->forward(c6), upsampled_[0]->forward(flow6)}, 1);
  Tensor flow5 = predict_[1]->forward(inter_[0]->forward(cat5));
  Tensor cat4 = concat({c4, deconv4_->forward(cat5), upsampled_[1]->forward(flow5)}, 1);
  Tensor flow4 = predict_[2]->forward(inter_[1]->forward(cat4));
  Tensor cat3 = concat({c3, deconv3_->forward(cat4), upsampled_[2]->forward(flow4)}, 1);
  Tensor flow3 = predict_[3]->forward(inter_[2]->forward(cat3));
  Tensor cat2 = concat({c2, deconv2_->forward(cat3), upsampled_[3]->forward(flow3)}, 1);
  return predict_[4]->forward(inter_[3]->forward(cat2));
}

// ---- FlowNetFusion -----------------------------------------------------------------------------

FlowNetFusion::FlowNetFusion(double width, Generator& gen) {
  auto s = [width](int64_t c) { return flownet_channels(c, width); };
  conv0_ = register_module("conv0", conv(11, s(64), 3, 1, gen));
  conv1_ = register_module("conv1", conv(s(64), s(64), 3, 2, gen));
  conv1_1_ = register_module("conv1_1", conv(s(64), s(128), 3, 1, gen));
  conv2_ = register_module("conv2", conv(s(128), s(128), 3, 2, gen));
  conv2_1_ = register_module("conv2_1", conv(s(128), s(128), 3, 1, gen));
  const int64_t cat1 = s(128) + s(32) + 2, cat0 = s(64) + s(16) + 2;
  deconv1_ = register_module("deconv1", deconv(s(128), s(32), gen));
  deconv0_ = register_module("deconv0", deconv(cat1, s(16), gen));
  inter_conv1_ = register_module("inter_conv1", i_conv(cat1, s(32), gen));
  inter_conv0_ = register_module("inter_conv0", i_conv(cat0, s(16), gen));
  predict_flow2_ = register_module("predict_flow2", predict_flow(s(128), gen));
  predict_flow1_ = register_module("predict_flow1", predict_flow(s(32), gen));
  predict_flow0_ = register_module("predict_flow0", predict_flow(s(16), gen));
  upsampled_flow2_to_1_ = register_module("upsampled_flow2_to_1", upsample_flow(true, gen));
  upsampled_flow1_to_0_ = register_module("upsampled_flow1_to_0", upsample_flow(true, gen));
}

Tensor FlowNetFusion::forward(const Tensor& x) {
  Tensor c0 = conv0_->forward(x);
  Tensor c1 = conv1_1_->forward(conv1_->forward(c0));
  Tensor c2 = conv2_1_->forward(conv2_->forward(c1));
  Tensor flow2 = predict_flow2_->forward(c2);
  Tensor cat1 = concat({c1, deconv1_->forward(c2), upsampled_flow2_to_1_->forward(flow2)}, 1);
  Tensor flow1 = predict_flow1_->forward(inter_conv1_->forward(cat1));
  Tensor cat0 = concat({c0, deconv0_->forward(cat1), upsampled_flow1_to_0_->forward(flow1)}, 1);
  return predict_flow0_->forward(inter_conv0_->forward(cat0));
}

}  // namespace cvd
