// The reduced Depth Anything V2 configuration that the fixture generators record in their
// header ("dav2_config"), shared by the parity and conversion tests.
#pragma once
#include <nlohmann/json.hpp>

#include "models/depth_anything_v2.h"

namespace cvd::test {

inline DepthAnythingConfig depth_anything_config_from(const nlohmann::json& j) {
  DepthAnythingConfig c;
  c.vit.embed_dim = j.at("embed_dim");
  c.vit.depth = j.at("depth");
  c.vit.heads = j.at("heads");
  c.vit.mlp_ratio = j.at("mlp_ratio");
  c.vit.patch = j.at("patch");
  c.vit.pos_grid = j.at("pos_grid");
  c.features = j.at("features");
  for (int i = 0; i < 4; ++i) {
    c.out_channels[i] = j.at("out_channels")[i];
    c.layers[i] = j.at("layers")[i];
  }
  return c;
}

}  // namespace cvd::test
