#include "models/depth_anything_v2.h"

#include "engine/ops.h"
#include "models/midas_blocks.h"

namespace cvd {

DepthAnythingConfig DepthAnythingConfig::vits() { return {}; }

DepthAnythingConfig DepthAnythingConfig::vitb() {
  DepthAnythingConfig c;
  c.arch = "depth_anything_v2_vitb";
  c.vit.embed_dim = 768;
  c.vit.heads = 12;
  c.features = 128;
  c.out_channels = {96, 192, 384, 768};
  return c;
}

DepthAnythingConfig DepthAnythingConfig::vitl() {
  DepthAnythingConfig c;
  c.arch = "depth_anything_v2_vitl";
  c.vit.embed_dim = 1024;
  c.vit.depth = 24;
  c.vit.heads = 16;
  c.features = 256;
  c.out_channels = {256, 512, 1024, 1024};
  c.layers = {4, 11, 17, 23};
  return c;
}

DepthAnythingConfig DepthAnythingConfig::scaled(DepthAnythingConfig c, double width) {
  const MidasWidth w(width, c.arch.c_str());
  c.vit.embed_dim = w(c.vit.embed_dim);
  CVD_CHECK(c.vit.embed_dim % c.vit.heads == 0,
            "{}: width {} leaves {} channels, not a multiple of {} heads", c.arch, width,
            c.vit.embed_dim, c.vit.heads);
  c.features = w(c.features);
  for (int64_t& o : c.out_channels) o = w(o);
  return c;
}

struct DepthAnythingV2Net::Parts {
  std::shared_ptr<VitEncoder> encoder;
  std::array<std::shared_ptr<Conv2d>, 4> projects, layer_rn;
  std::shared_ptr<ConvTranspose2d> resize0, resize1;
  std::shared_ptr<Conv2d> resize3;
  std::array<std::shared_ptr<FeatureFusionBlock>, 4> refinenet;  // [0] = refinenet1
  std::shared_ptr<Conv2d> output_conv1;
  std::shared_ptr<Sequential> output_conv2;
  std::shared_ptr<Conv2d> output_layer;
};

DepthAnythingV2Net::DepthAnythingV2Net(const DepthAnythingConfig& config, Generator& gen)
    : config_(config), parts_(std::make_unique<Parts>()) {
  Parts& p = *parts_;
  const int64_t c = config.vit.embed_dim, f = config.features;
  const auto& oc = config.out_channels;
  for (int l : config.layers)
    CVD_CHECK(l >= 0 && l < config.vit.depth, "{}: layer {} of a {}-block encoder", config.arch, l,
              config.vit.depth);
  p.encoder = register_module("pretrained", std::make_shared<VitEncoder>(config.vit, gen));
  auto head = register_module("depth_head", std::make_shared<ModuleGroup>());
  auto projects = head->add("projects", std::make_shared<ModuleGroup>());
  for (int i = 0; i < 4; ++i)
    p.projects[i] =
        projects->add(std::to_string(i), std::make_shared<Conv2d>(Conv2dOptions(c, oc[i], 1), gen));
  auto resize = head->add("resize_layers", std::make_shared<ModuleGroup>());
  p.resize0 = resize->add("0", std::make_shared<ConvTranspose2d>(
                                   ConvTranspose2dOptions(oc[0], oc[0], 4).with_stride(4), gen));
  p.resize1 = resize->add("1", std::make_shared<ConvTranspose2d>(
                                   ConvTranspose2dOptions(oc[1], oc[1], 2).with_stride(2), gen));
  resize->add("2", std::make_shared<Identity>());
  p.resize3 = resize->add(
      "3",
      std::make_shared<Conv2d>(Conv2dOptions(oc[3], oc[3], 3).with_stride(2).with_padding(1), gen));
  auto scratch = head->add("scratch", std::make_shared<ModuleGroup>());
  for (int i = 0; i < 4; ++i)
    p.layer_rn[i] = scratch->add(
        "layer" + std::to_string(i + 1) + "_rn",
        std::make_shared<Conv2d>(Conv2dOptions(oc[i], f, 3).with_padding(1).with_bias(false), gen));
  for (int i = 0; i < 4; ++i)
    p.refinenet[i] = scratch->add("refinenet" + std::to_string(i + 1),
                                  std::make_shared<FeatureFusionBlock>(f, f, true, gen));
  p.output_conv1 = scratch->add(
      "output_conv1", std::make_shared<Conv2d>(Conv2dOptions(f, f / 2, 3).with_padding(1), gen));
  p.output_conv2 = scratch->add("output_conv2", std::make_shared<Sequential>());
  p.output_conv2->push_back(
      std::make_shared<Conv2d>(Conv2dOptions(f / 2, 32, 3).with_padding(1), gen));
  p.output_conv2->push_back(std::make_shared<ReLU>());
  p.output_layer =
      p.output_conv2->push_back(std::make_shared<Conv2d>(Conv2dOptions(32, 1, 1), gen));
  p.output_conv2->push_back(std::make_shared<ReLU>());
  p.output_conv2->push_back(std::make_shared<Identity>());
}

DepthAnythingV2Net::~DepthAnythingV2Net() = default;

Tensor DepthAnythingV2Net::normalize_input(const Tensor& rgb01) const {
  return imagenet_normalize(rgb01);
}

Tensor DepthAnythingV2Net::forward_raw(const Tensor& x) {
  const int patch = config_.vit.patch;
  CVD_CHECK(x.dim() == 4 && x.size(1) == 3 && x.size(2) % patch == 0 && x.size(3) % patch == 0,
            "{}: input {} must be [N, 3, H, W] with H and W multiples of {}", config_.arch, x.str(),
            patch);
  Parts& p = *parts_;
  const int64_t n = x.size(0), ph = x.size(2) / patch, pw = x.size(3) / patch;
  const std::vector<int> layers(config_.layers.begin(), config_.layers.end());
  const std::vector<Tensor> tokens = p.encoder->intermediate_layers(x, layers);
  std::array<Tensor, 4> rn;
  for (int i = 0; i < 4; ++i) {
    // [N, ph * pw, C] -> [N, C, ph, pw]
    Tensor m = reshape(transpose(tokens[i], 1, 2), {n, config_.vit.embed_dim, ph, pw});
    m = p.projects[i]->forward(m);
    if (i == 0) m = p.resize0->forward(m);
    if (i == 1) m = p.resize1->forward(m);
    if (i == 3) m = p.resize3->forward(m);
    rn[i] = p.layer_rn[i]->forward(m);
  }
  Tensor path = p.refinenet[3]->forward_to(rn[3], rn[2].size(2), rn[2].size(3));
  path = p.refinenet[2]->forward_to(path, rn[2], rn[1].size(2), rn[1].size(3));
  path = p.refinenet[1]->forward_to(path, rn[1], rn[0].size(2), rn[0].size(3));
  path = p.refinenet[0]->forward(path, rn[0]);
  Tensor out = p.output_conv1->forward(path);
  out = upsample_bilinear2d(out, ph * patch, pw * patch, /*align_corners=*/true);
  return relu(p.output_conv2->forward(out));
}

Tensor DepthAnythingV2Net::output_bias() { return parts_->output_layer->bias; }
Tensor DepthAnythingV2Net::output_weight() { return parts_->output_layer->weight; }

std::vector<std::string> DepthAnythingV2Net::execution_order() const {
  std::vector<std::string> order{"pretrained"};
  for (int i = 0; i < 4; ++i) {
    order.push_back("depth_head.projects." + std::to_string(i));
    if (i != 2) order.push_back("depth_head.resize_layers." + std::to_string(i));
  }
  for (int i = 1; i <= 4; ++i)
    order.push_back("depth_head.scratch.layer" + std::to_string(i) + "_rn");
  for (int i = 4; i >= 1; --i) {
    const std::string r = "depth_head.scratch.refinenet" + std::to_string(i);
    if (i != 4) order.push_back(r + ".resConfUnit1");
    order.insert(order.end(), {r + ".resConfUnit2", r + ".out_conv"});
  }
  order.insert(order.end(), {"depth_head.scratch.output_conv1", "depth_head.scratch.output_conv2"});
  return order;
}

}  // namespace cvd
