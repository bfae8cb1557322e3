// The DINOv2 vision transformer (facebookresearch/dinov2, as vendored by Depth Anything V2):
// patch embedding, class token, a position embedding interpolated to the input's patch grid,
// pre-norm blocks with LayerScale, and a final LayerNorm. Names and parameter order follow the
// released state dicts ("cls_token", "pos_embed", "mask_token", "patch_embed.proj.weight",
// "blocks.3.attn.qkv.weight", "blocks.3.ls1.gamma", "norm.bias", ...). Layer table: docs/models.md.
//
// Position embedding (DinoVisionTransformer.interpolate_pos_encoding): unchanged when the input is
// square with the embedding's grid; otherwise its M x M patch part is resized bicubically
// (PyTorch, A = -0.75, no antialias) to the patch grid with the scale factors (n + 0.1) / M, as
// DINOv2 passes them (so the source coordinates use those factors, not n / M).
#pragma once
#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "engine/layers.h"
#include "models/midas_blocks.h"

namespace cvd {

struct VitConfig {
  int64_t embed_dim = 384;
  int64_t depth = 12;
  int64_t heads = 6;
  int64_t mlp_ratio = 4;
  int patch = 14;
  int64_t pos_grid = 37;  // the position embedding's grid side (img_size 518 / patch 14)
  double layer_scale_init = 1.0;
};

// x * gamma ("gamma" [C]).
class LayerScale : public Module {
 public:
  LayerScale(int64_t dim, double init);
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override { return "LayerScale"; }
  Tensor gamma;
};

// Multi-head self-attention on [B, N, C]: qkv Linear(C, 3C), softmax(q k^T / sqrt(d)) v per head,
// proj Linear(C, C).
class VitAttention : public Module {
 public:
  VitAttention(int64_t dim, int64_t heads, Generator& gen);
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override { return "Attention"; }

 private:
  int64_t heads_;
  std::shared_ptr<Linear> qkv_, proj_;
};

// fc1 (C -> hidden), GELU, fc2 (hidden -> C).
class VitMlp : public Module {
 public:
  VitMlp(int64_t dim, int64_t hidden, Generator& gen);
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override { return "Mlp"; }

 private:
  std::shared_ptr<Linear> fc1_, fc2_;
};

// x = x + ls1(attn(norm1(x))); x = x + ls2(mlp(norm2(x))). LayerNorm eps 1e-6.
class VitBlock : public Module {
 public:
  VitBlock(const VitConfig& c, Generator& gen);
  Tensor forward(const Tensor& x) override;
  std::string type_name() const override { return "NestedTensorBlock"; }

 private:
  std::shared_ptr<LayerNorm> norm1_, norm2_;
  std::shared_ptr<VitAttention> attn_;
  std::shared_ptr<VitMlp> mlp_;
  std::shared_ptr<LayerScale> ls1_, ls2_;
};

class VitEncoder : public Module {
 public:
  VitEncoder(const VitConfig& c, Generator& gen);
  // The final-normed patch tokens [N, ph * pw, C] after each block of `layers` (indices from 0),
  // for an input [N, 3, ph * patch, pw * patch].
  std::vector<Tensor> intermediate_layers(const Tensor& x, const std::vector<int>& layers);
  // The position embedding for a ph x pw patch grid of an H x W input: [1, 1 + ph * pw, C].
  Tensor position_embedding(int64_t ph, int64_t pw, int64_t h, int64_t w) const;
  std::string type_name() const override { return "DinoVisionTransformer"; }
  const VitConfig& config() const { return c_; }

  Tensor cls_token;   // [1, 1, C]
  Tensor pos_embed;   // [1, 1 + M * M, C]
  Tensor mask_token;  // [1, C]: masked pre-training only, never used here (kept for the state)

 private:
  VitConfig c_;
  std::shared_ptr<Conv2d> patch_proj_;
  std::vector<std::shared_ptr<VitBlock>> blocks_;
  std::shared_ptr<LayerNorm> norm_;
};

}  // namespace cvd
