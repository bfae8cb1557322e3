#include "models/midas_v2.h"

#include "engine/layers.h"
#include "engine/ops.h"
#include "models/midas_blocks.h"
#include "models/upsample.h"

namespace cvd {

namespace {

// torchvision ResNeXt Bottleneck ("v1.5": the stride sits in the grouped 3x3 conv).
class Bottleneck : public Module {
 public:
  Bottleneck(int64_t in, int64_t width, int64_t out, int stride, int groups, Generator& gen) {
    conv1_ = register_module(
        "conv1", std::make_shared<Conv2d>(Conv2dOptions(in, width, 1).with_bias(false), gen));
    bn1_ = register_module("bn1", std::make_shared<BatchNorm2d>(BatchNorm2dOptions(width)));
    conv2_ = register_module("conv2", std::make_shared<Conv2d>(Conv2dOptions(width, width, 3)
                                                                   .with_stride(stride)
                                                                   .with_padding(1)
                                                                   .with_groups(groups)
                                                                   .with_bias(false),
                                                               gen));
    bn2_ = register_module("bn2", std::make_shared<BatchNorm2d>(BatchNorm2dOptions(width)));
    conv3_ = register_module(
        "conv3", std::make_shared<Conv2d>(Conv2dOptions(width, out, 1).with_bias(false), gen));
    bn3_ = register_module("bn3", std::make_shared<BatchNorm2d>(BatchNorm2dOptions(out)));
    if (stride != 1 || in != out) {
      downsample_ = register_module("downsample", std::make_shared<Sequential>());
      downsample_->push_back(std::make_shared<Conv2d>(
          Conv2dOptions(in, out, 1).with_stride(stride).with_bias(false), gen));
      downsample_->push_back(std::make_shared<BatchNorm2d>(BatchNorm2dOptions(out)));
    }
  }
  Tensor forward(const Tensor& x) override {
    Tensor y = bn1_->forward_act(conv1_->forward(x), {UnaryOp::relu});
    y = bn2_->forward_act(conv2_->forward(y), {UnaryOp::relu});
    y = bn3_->forward(conv3_->forward(y));
    return relu(add(y, downsample_ ? downsample_->forward(x) : x));
  }
  std::string type_name() const override { return "Bottleneck"; }

 private:
  std::shared_ptr<Conv2d> conv1_, conv2_, conv3_;
  std::shared_ptr<BatchNorm2d> bn1_, bn2_, bn3_;
  std::shared_ptr<Sequential> downsample_;
};

// torchvision ResNet._make_layer for ResNeXt 32x8d: bottleneck width = planes * 4 (= planes *
// 8 / 64 * 32), output planes * 4.
std::shared_ptr<Sequential> resnext_layer(int64_t& in, int64_t planes, int blocks, int stride,
                                          const MidasWidth& w, int groups, Generator& gen) {
  const int64_t width = w(planes * 4), out = w(planes * 4);
  auto layer = std::make_shared<Sequential>();
  layer->push_back(std::make_shared<Bottleneck>(in, width, out, stride, groups, gen));
  for (int i = 1; i < blocks; ++i) {
    layer->push_back(std::make_shared<Bottleneck>(out, width, out, 1, groups, gen));
  }
  in = out;
  return layer;
}

}  // namespace

struct MidasV2Net::Parts {
  std::shared_ptr<Sequential> layer1, layer2, layer3, layer4;
  std::shared_ptr<Conv2d> layer1_rn, layer2_rn, layer3_rn, layer4_rn;
  std::shared_ptr<FeatureFusionBlock> refinenet4, refinenet3, refinenet2, refinenet1;
  std::shared_ptr<Sequential> output_conv;
  std::shared_ptr<Conv2d> output_layer;
};

MidasV2Net::~MidasV2Net() = default;

MidasV2Net::MidasV2Net(double width, Generator& gen) : parts_(std::make_unique<Parts>()) {
  const MidasWidth w(width, "midas_v2");
  const int groups = static_cast<int>(std::min<int64_t>(32, w(256)));
  const int64_t stem = w(64), features = w(256);
  Parts& p = *parts_;

  auto pretrained = register_module("pretrained", std::make_shared<ModuleGroup>());
  auto scratch = register_module("scratch", std::make_shared<ModuleGroup>());

  // pretrained.layer1 = Sequential(conv1, bn1, relu, maxpool, resnet.layer1).
  p.layer1 = pretrained->add("layer1", std::make_shared<Sequential>());
  p.layer1->push_back(std::make_shared<Conv2d>(
      Conv2dOptions(3, stem, 7).with_stride(2).with_padding(3).with_bias(false), gen));
  p.layer1->push_back(std::make_shared<BatchNorm2d>(BatchNorm2dOptions(stem)));
  p.layer1->push_back(std::make_shared<ReLU>());
  Pool2dParams maxpool;
  maxpool.kernel_h = maxpool.kernel_w = 3;
  maxpool.stride_h = maxpool.stride_w = 2;
  maxpool.pad_top = maxpool.pad_bottom = maxpool.pad_left = maxpool.pad_right = 1;
  p.layer1->push_back(std::make_shared<MaxPool2d>(maxpool));
  int64_t c = stem;
  p.layer1->push_back(resnext_layer(c, 64, 3, 1, w, groups, gen));
  const int64_t c1 = c;
  p.layer2 = pretrained->add("layer2", resnext_layer(c, 128, 4, 2, w, groups, gen));
  const int64_t c2 = c;
  p.layer3 = pretrained->add("layer3", resnext_layer(c, 256, 23, 2, w, groups, gen));
  const int64_t c3 = c;
  p.layer4 = pretrained->add("layer4", resnext_layer(c, 512, 3, 2, w, groups, gen));
  const int64_t c4 = c;

  auto rn = [&](const char* name, int64_t in) {
    return scratch->add(name,
                        std::make_shared<Conv2d>(
                            Conv2dOptions(in, features, 3).with_padding(1).with_bias(false), gen));
  };
  p.layer1_rn = rn("layer1_rn", c1);
  p.layer2_rn = rn("layer2_rn", c2);
  p.layer3_rn = rn("layer3_rn", c3);
  p.layer4_rn = rn("layer4_rn", c4);
  // refinenet4 gets no skip input: its resConfUnit1 (present, unused, in the released file) is
  // not built.
  p.refinenet4 =
      scratch->add("refinenet4", std::make_shared<FeatureFusionBlock>(features, false, gen));
  p.refinenet3 =
      scratch->add("refinenet3", std::make_shared<FeatureFusionBlock>(features, true, gen));
  p.refinenet2 =
      scratch->add("refinenet2", std::make_shared<FeatureFusionBlock>(features, true, gen));
  p.refinenet1 =
      scratch->add("refinenet1", std::make_shared<FeatureFusionBlock>(features, true, gen));

  // Conv3x3 -> Up x2 (align_corners=False) -> Conv3x3 -> ReLU -> Conv1x1 -> ReLU.
  const int64_t h128 = w(128), h32 = w(32);
  p.output_conv = scratch->add("output_conv", std::make_shared<Sequential>());
  p.output_conv->push_back(
      std::make_shared<Conv2d>(Conv2dOptions(features, h128, 3).with_padding(1), gen));
  p.output_conv->push_back(std::make_shared<Upsample>(2, UpsampleMode::bilinear));
  p.output_conv->push_back(
      std::make_shared<Conv2d>(Conv2dOptions(h128, h32, 3).with_padding(1), gen));
  p.output_conv->push_back(std::make_shared<ReLU>());
  p.output_layer =
      p.output_conv->push_back(std::make_shared<Conv2d>(Conv2dOptions(h32, 1, 1), gen));
  p.output_conv->push_back(std::make_shared<ReLU>());
}

Tensor MidasV2Net::normalize_input(const Tensor& rgb01) const { return imagenet_normalize(rgb01); }

Tensor MidasV2Net::forward_raw(const Tensor& x) {
  CVD_CHECK(x.dim() == 4 && x.size(1) == 3 && x.size(2) % 32 == 0 && x.size(3) % 32 == 0,
            "midas_v2: input {} must be [N, 3, H, W] with H and W multiples of 32", x.str());
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

Tensor MidasV2Net::output_bias() { return parts_->output_layer->bias; }
Tensor MidasV2Net::output_weight() { return parts_->output_layer->weight; }

}  // namespace cvd
