#include "models/midas_small.h"

#include <array>

#include "engine/layers.h"
#include "engine/ops.h"
#include "models/midas_blocks.h"
#include "models/upsample.h"

namespace cvd {

namespace {

// Conv without bias with TF "SAME" padding for inputs whose size divides by the stride.
std::shared_ptr<Conv2d> same_conv(int64_t in, int64_t out, int k, int stride, int groups,
                                  Generator& gen) {
  const int total = std::max(k - stride, 0);
  const int before = total / 2, after = total - total / 2;
  return std::make_shared<Conv2d>(Conv2dOptions(in, out, k)
                                      .with_stride(stride)
                                      .with_padding(before, after, before, after)
                                      .with_groups(groups)
                                      .with_bias(false),
                                  gen);
}

const UnaryParams kRelu6{UnaryOp::clip, 0.0, 6.0};

std::shared_ptr<BatchNorm2d> bn_tf(int64_t c) {
  return std::make_shared<BatchNorm2d>(BatchNorm2dOptions(c).with_eps(1e-3));
}

// gen-efficientnet DepthwiseSeparableConv (pw_act=False, no SE): dw kxk -> BN -> ReLU6 -> pw 1x1
// -> BN.
class DepthwiseSeparableConv : public Module {
 public:
  DepthwiseSeparableConv(int64_t in, int64_t out, int k, Generator& gen) {
    conv_dw_ = register_module("conv_dw", same_conv(in, in, k, 1, static_cast<int>(in), gen));
    bn1_ = register_module("bn1", bn_tf(in));
    conv_pw_ = register_module("conv_pw", same_conv(in, out, 1, 1, 1, gen));
    bn2_ = register_module("bn2", bn_tf(out));
  }
  Tensor forward(const Tensor& x) override {
    return bn2_->forward(conv_pw_->forward(bn1_->forward_act(conv_dw_->forward(x), kRelu6)));
  }
  std::string type_name() const override { return "DepthwiseSeparableConv"; }

 private:
  std::shared_ptr<Conv2d> conv_dw_, conv_pw_;
  std::shared_ptr<BatchNorm2d> bn1_, bn2_;
};

// gen-efficientnet InvertedResidual (no SE): pw 1x1 -> BN -> ReLU6 -> dw kxk (stride) -> BN ->
// ReLU6 -> pw 1x1 -> BN (+ x when `residual`).
class InvertedResidual : public Module {
 public:
  InvertedResidual(int64_t in, int64_t out, int k, int stride, bool residual, Generator& gen)
      : residual_(residual) {
    const int64_t mid = 6 * in;
    conv_pw_ = register_module("conv_pw", same_conv(in, mid, 1, 1, 1, gen));
    bn1_ = register_module("bn1", bn_tf(mid));
    conv_dw_ =
        register_module("conv_dw", same_conv(mid, mid, k, stride, static_cast<int>(mid), gen));
    bn2_ = register_module("bn2", bn_tf(mid));
    conv_pwl_ = register_module("conv_pwl", same_conv(mid, out, 1, 1, 1, gen));
    bn3_ = register_module("bn3", bn_tf(out));
  }
  Tensor forward(const Tensor& x) override {
    Tensor y = bn1_->forward_act(conv_pw_->forward(x), kRelu6);
    y = bn2_->forward_act(conv_dw_->forward(y), kRelu6);
    y = bn3_->forward(conv_pwl_->forward(y));
    return residual_ ? add(y, x) : y;
  }
  std::string type_name() const override { return "InvertedResidual"; }

 private:
  std::shared_ptr<Conv2d> conv_pw_, conv_dw_, conv_pwl_;
  std::shared_ptr<BatchNorm2d> bn1_, bn2_, bn3_;
  bool residual_;
};

// tf_efficientnet_lite3 stages 1..6 after channel x1.2 (divisor 8) and depth x1.4 (ceil, last
// stage fixed).
struct Stage {
  int repeats, kernel, stride;
  int64_t out;
};
constexpr std::array<Stage, 6> kLite3Stages{
    {{3, 3, 2, 32}, {3, 5, 2, 48}, {5, 3, 2, 96}, {5, 5, 1, 136}, {6, 5, 2, 232}, {1, 3, 1, 384}}};

// One stage as a Sequential of blocks; `in` becomes the stage's output width.
std::shared_ptr<Sequential> efficientnet_stage(int64_t& in, const Stage& s, const MidasWidth& w,
                                               Generator& gen) {
  const int64_t out = w(s.out);
  auto stage = std::make_shared<Sequential>();
  for (int i = 0; i < s.repeats; ++i) {
    stage->push_back(std::make_shared<InvertedResidual>(i == 0 ? in : out, out, s.kernel,
                                                        i == 0 ? s.stride : 1, i > 0, gen));
  }
  in = out;
  return stage;
}

}  // namespace

struct MidasSmallNet::Parts {
  std::shared_ptr<Sequential> layer1, layer2, layer3, layer4;
  std::shared_ptr<Conv2d> layer1_rn, layer2_rn, layer3_rn, layer4_rn;
  std::shared_ptr<FeatureFusionBlock> refinenet4, refinenet3, refinenet2, refinenet1;
  std::shared_ptr<Sequential> output_conv;
  std::shared_ptr<Conv2d> output_layer;
};

MidasSmallNet::~MidasSmallNet() = default;

MidasSmallNet::MidasSmallNet(double width, Generator& gen) : parts_(std::make_unique<Parts>()) {
  const MidasWidth w(width, "midas_small");
  Parts& p = *parts_;
  auto pretrained = register_module("pretrained", std::make_shared<ModuleGroup>());
  auto scratch = register_module("scratch", std::make_shared<ModuleGroup>());

  // layer1 = conv_stem, bn1, act1, blocks[0] (one depthwise-separable block), blocks[1].
  const int64_t stem = w(32), c0 = w(24);
  p.layer1 = pretrained->add("layer1", std::make_shared<Sequential>());
  p.layer1->push_back(same_conv(3, stem, 3, 2, 1, gen));
  p.layer1->push_back(bn_tf(stem));
  p.layer1->push_back(std::make_shared<ReLU6>());
  auto block0 = p.layer1->push_back(std::make_shared<Sequential>());
  block0->push_back(std::make_shared<DepthwiseSeparableConv>(stem, c0, 3, gen));
  int64_t c = c0;
  p.layer1->push_back(efficientnet_stage(c, kLite3Stages[0], w, gen));
  const int64_t c1 = c;
  p.layer2 = pretrained->add("layer2", std::make_shared<Sequential>());
  p.layer2->push_back(efficientnet_stage(c, kLite3Stages[1], w, gen));
  const int64_t c2 = c;
  p.layer3 = pretrained->add("layer3", std::make_shared<Sequential>());
  p.layer3->push_back(efficientnet_stage(c, kLite3Stages[2], w, gen));
  p.layer3->push_back(efficientnet_stage(c, kLite3Stages[3], w, gen));
  const int64_t c3 = c;
  p.layer4 = pretrained->add("layer4", std::make_shared<Sequential>());
  p.layer4->push_back(efficientnet_stage(c, kLite3Stages[4], w, gen));
  p.layer4->push_back(efficientnet_stage(c, kLite3Stages[5], w, gen));
  const int64_t c4 = c;

  // expand=True: the decoder widths are f, 2f, 4f, 8f; each fusion block halves its width in
  // its 1x1 out_conv except refinenet1.
  const int64_t f = w(64);
  auto rn = [&](const char* name, int64_t in, int64_t out) {
    return scratch->add(name, std::make_shared<Conv2d>(
                                  Conv2dOptions(in, out, 3).with_padding(1).with_bias(false), gen));
  };
  p.layer1_rn = rn("layer1_rn", c1, f);
  p.layer2_rn = rn("layer2_rn", c2, 2 * f);
  p.layer3_rn = rn("layer3_rn", c3, 4 * f);
  p.layer4_rn = rn("layer4_rn", c4, 8 * f);
  auto ffb = [&](const char* name, int64_t features, int64_t out, bool skip) {
    return scratch->add(name, std::make_shared<FeatureFusionBlock>(features, out, skip, gen));
  };
  p.refinenet4 = ffb("refinenet4", 8 * f, 4 * f, false);
  p.refinenet3 = ffb("refinenet3", 4 * f, 2 * f, true);
  p.refinenet2 = ffb("refinenet2", 2 * f, f, true);
  p.refinenet1 = ffb("refinenet1", f, f, true);

  // Conv3x3 f -> f/2 -> Up x2 (align_corners=False) -> Conv3x3 -> ReLU -> Conv1x1 -> ReLU ->
  // Identity.
  const int64_t h = w(32);
  p.output_conv = scratch->add("output_conv", std::make_shared<Sequential>());
  p.output_conv->push_back(std::make_shared<Conv2d>(Conv2dOptions(f, h, 3).with_padding(1), gen));
  p.output_conv->push_back(std::make_shared<Upsample>(2, UpsampleMode::bilinear));
  p.output_conv->push_back(std::make_shared<Conv2d>(Conv2dOptions(h, h, 3).with_padding(1), gen));
  p.output_conv->push_back(std::make_shared<ReLU>());
  p.output_layer = p.output_conv->push_back(std::make_shared<Conv2d>(Conv2dOptions(h, 1, 1), gen));
  p.output_conv->push_back(std::make_shared<ReLU>());
  p.output_conv->push_back(std::make_shared<Identity>());
}

Tensor MidasSmallNet::normalize_input(const Tensor& rgb01) const {
  return imagenet_normalize(rgb01);
}

Tensor MidasSmallNet::forward_raw(const Tensor& x) {
  CVD_CHECK(x.dim() == 4 && x.size(1) == 3 && x.size(2) % 32 == 0 && x.size(3) % 32 == 0,
            "midas_small: input {} must be [N, 3, H, W] with H and W multiples of 32", x.str());
  Parts& p = *parts_;
  const Tensor l1 = p.layer1->forward(x);
  const Tensor l2 = p.layer2->forward(l1);
  const Tensor l3 = p.layer3->forward(l2);
  const Tensor l4 = p.layer4->forward(l3);
  const Tensor l1_rn = p.layer1_rn->forward(l1);
  const Tensor l2_rn = p.layer2_rn->forward(l2);
  const Tensor l3_rn = p.layer3_rn->forward(l3);
  const Tensor l4_rn = p.layer4_rn->forward(l4);
  Tensor path = p.refinenet4->forward(l4_rn);
  path = p.refinenet3->forward(path, l3_rn);
  path = p.refinenet2->forward(path, l2_rn);
  path = p.refinenet1->forward(path, l1_rn);
  return p.output_conv->forward(path);
}

Tensor MidasSmallNet::output_bias() { return parts_->output_layer->bias; }
Tensor MidasSmallNet::output_weight() { return parts_->output_layer->weight; }

}  // namespace cvd
