#include "models/vit_encoder.h"

#include <cmath>

#include "engine/ops.h"

namespace cvd {

namespace {

// N(0, std) truncated to [-2, 2] (timm's trunc_normal_ with its default absolute bounds).
Tensor truncated_normal(const Shape& shape, double std, Generator& gen) {
  int64_t n = 1;
  for (int64_t d : shape) n *= d;
  std::vector<double> v(static_cast<size_t>(n));
  for (double& x : v) {
    do {
      x = gen.normal() * std;
    } while (x < -2.0 || x > 2.0);
  }
  return Tensor::from_vector(v, shape, DType::f32);
}

// timm's ViT init of a Linear: weight ~ trunc_normal(0.02), bias 0.
std::shared_ptr<Linear> vit_linear(int64_t in, int64_t out, Generator& gen) {
  auto l = std::make_shared<Linear>(in, out, gen);
  replace_tensor_data(l->weight, truncated_normal({out, in}, 0.02, gen));
  replace_tensor_data(l->bias, Tensor::full({out}, 0.0));
  return l;
}

}  // namespace

LayerScale::LayerScale(int64_t dim, double init) {
  gamma = register_parameter("gamma", Tensor::full({dim}, init));
}

Tensor LayerScale::forward(const Tensor& x) { return mul(x, gamma); }

VitAttention::VitAttention(int64_t dim, int64_t heads, Generator& gen) : heads_(heads) {
  CVD_CHECK(heads > 0 && dim % heads == 0, "Attention: width {} is not a multiple of {} heads", dim,
            heads);
  qkv_ = register_module("qkv", vit_linear(dim, 3 * dim, gen));
  proj_ = register_module("proj", vit_linear(dim, dim, gen));
}

Tensor VitAttention::forward(const Tensor& x) {
  const int64_t b = x.size(0), n = x.size(1), c = x.size(2), d = c / heads_;
  // [B, N, 3, H, d] -> [3, B, H, N, d]
  const Tensor qkv = permute(reshape(qkv_->forward(x), {b, n, 3, heads_, d}), {2, 0, 3, 1, 4});
  const Tensor q = mul_scalar(squeeze(narrow(qkv, 0, 0, 1), 0), 1.0 / std::sqrt(double(d)));
  const Tensor k = squeeze(narrow(qkv, 0, 1, 1), 0);
  const Tensor v = squeeze(narrow(qkv, 0, 2, 1), 0);
  const Tensor attn = softmax(matmul(q, transpose(k, -2, -1)));  // [B, H, N, N]
  const Tensor out = reshape(transpose(matmul(attn, v), 1, 2), {b, n, c});
  return proj_->forward(out);
}

VitMlp::VitMlp(int64_t dim, int64_t hidden, Generator& gen) {
  fc1_ = register_module("fc1", vit_linear(dim, hidden, gen));
  register_module("act", std::make_shared<GELU>());
  fc2_ = register_module("fc2", vit_linear(hidden, dim, gen));
}

Tensor VitMlp::forward(const Tensor& x) { return fc2_->forward(gelu(fc1_->forward(x))); }

VitBlock::VitBlock(const VitConfig& c, Generator& gen) {
  norm1_ = register_module("norm1", std::make_shared<LayerNorm>(c.embed_dim, 1e-6));
  attn_ = register_module("attn", std::make_shared<VitAttention>(c.embed_dim, c.heads, gen));
  ls1_ = register_module("ls1", std::make_shared<LayerScale>(c.embed_dim, c.layer_scale_init));
  norm2_ = register_module("norm2", std::make_shared<LayerNorm>(c.embed_dim, 1e-6));
  mlp_ =
      register_module("mlp", std::make_shared<VitMlp>(c.embed_dim, c.embed_dim * c.mlp_ratio, gen));
  ls2_ = register_module("ls2", std::make_shared<LayerScale>(c.embed_dim, c.layer_scale_init));
}

Tensor VitBlock::forward(const Tensor& x) {
  const Tensor h = add(x, ls1_->forward(attn_->forward(norm1_->forward(x))));
  return add(h, ls2_->forward(mlp_->forward(norm2_->forward(h))));
}

VitEncoder::VitEncoder(const VitConfig& c, Generator& gen) : c_(c) {
  CVD_CHECK(c.embed_dim > 0 && c.depth > 0 && c.patch > 0 && c.pos_grid > 0 && c.mlp_ratio > 0,
            "DINOv2 encoder: invalid configuration");
  // PyTorch lists the root's own parameters first: cls_token, pos_embed, mask_token.
  cls_token = register_parameter("cls_token",
                                 mul_scalar(truncated_normal({1, 1, c.embed_dim}, 1.0, gen), 1e-6));
  pos_embed = register_parameter(
      "pos_embed", truncated_normal({1, 1 + c.pos_grid * c.pos_grid, c.embed_dim}, 0.02, gen));
  mask_token = register_parameter("mask_token", Tensor::full({1, c.embed_dim}, 0.0));
  auto patch_embed = register_module("patch_embed", std::make_shared<ModuleGroup>());
  patch_proj_ = patch_embed->add(
      "proj",
      std::make_shared<Conv2d>(Conv2dOptions(3, c.embed_dim, c.patch).with_stride(c.patch), gen));
  auto blocks = register_module("blocks", std::make_shared<ModuleGroup>());
  for (int64_t i = 0; i < c.depth; ++i)
    blocks_.push_back(blocks->add(std::to_string(i), std::make_shared<VitBlock>(c, gen)));
  norm_ = register_module("norm", std::make_shared<LayerNorm>(c.embed_dim, 1e-6));
}

Tensor VitEncoder::position_embedding(int64_t ph, int64_t pw, int64_t h, int64_t w) const {
  const int64_t m = c_.pos_grid, dim = c_.embed_dim;
  if (ph * pw == m * m && h == w) return pos_embed;
  const Tensor cls_pos = narrow(pos_embed, 1, 0, 1);  // [1, 1, C]
  Tensor grid = permute(reshape(narrow(pos_embed, 1, 1, m * m), {1, m, m, dim}), {0, 3, 1, 2});
  grid = upsample_bicubic2d(grid, ph, pw, /*align_corners=*/false, (double(ph) + 0.1) / double(m),
                            (double(pw) + 0.1) / double(m));
  const Tensor patches = reshape(permute(grid, {0, 2, 3, 1}), {1, ph * pw, dim});
  return concat({cls_pos, patches}, 1);
}

std::vector<Tensor> VitEncoder::intermediate_layers(const Tensor& x,
                                                    const std::vector<int>& layers) {
  CVD_CHECK(
      x.dim() == 4 && x.size(1) == 3 && x.size(2) % c_.patch == 0 && x.size(3) % c_.patch == 0,
      "DINOv2 encoder: input {} must be [N, 3, H, W] with H and W multiples of {}", x.str(),
      c_.patch);
  const int64_t n = x.size(0), ph = x.size(2) / c_.patch, pw = x.size(3) / c_.patch;
  // [N, C, ph, pw] -> [N, ph * pw, C], the class token in front, plus the position embedding.
  Tensor t = transpose(reshape(patch_proj_->forward(x), {n, c_.embed_dim, ph * pw}), 1, 2);
  t = concat({expand(cls_token, {n, 1, c_.embed_dim}), t}, 1);
  t = add(t, position_embedding(ph, pw, x.size(2), x.size(3)));
  std::vector<Tensor> out;
  for (size_t i = 0; i < blocks_.size(); ++i) {
    t = blocks_[i]->forward(t);
    for (int l : layers)
      if (l == static_cast<int>(i)) out.push_back(narrow(norm_->forward(t), 1, 1, ph * pw));
  }
  CVD_CHECK(out.size() == layers.size(), "DINOv2 encoder: layers out of range (depth {})",
            c_.depth);
  return out;
}

}  // namespace cvd
