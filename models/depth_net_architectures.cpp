#include "models/depth_net_architectures.h"

#include <fmt/format.h>

#include "engine/error.h"
#include "models/depth_anything_v2.h"
#include "models/mannequin.h"
#include "models/midas_small.h"
#include "models/midas_v2.h"

namespace cvd {

namespace {

template <class Net>
std::unique_ptr<DepthNet> make(double width, Generator& gen) {
  return std::make_unique<Net>(width, gen);
}

template <DepthAnythingConfig (*Base)()>
std::unique_ptr<DepthNet> make_depth_anything(double width, Generator& gen) {
  return std::make_unique<DepthAnythingV2Net>(DepthAnythingConfig::scaled(Base(), width), gen);
}

}  // namespace

const std::vector<DepthNetArchitecture>& depth_net_architectures() {
  // lr / lambda: the reference implementation's values for Mannequin (Adam 4e-4, lambda 0.1);
  // MiDaS predicts inverse depth at another scale, where 1e-4 / 1e-4 were measured stable.
  static const std::vector<DepthNetArchitecture> table = {
      {"mannequin", &make<MannequinNet>, DepthOutputKind::log_depth, 16, 4e-4, 0.1,
       "Mannequin Challenge hourglass (log depth)"},
      {"midas_v2", &make<MidasV2Net>, DepthOutputKind::inverse_depth, 32, 1e-4, 1e-4,
       "MiDaS v2, ResNeXt-101 encoder (inverse depth)"},
      {"midas_small", &make<MidasSmallNet>, DepthOutputKind::inverse_depth, 32, 1e-4, 1e-4,
       "MiDaS v2.1 small, EfficientNet-Lite3 encoder (inverse depth)"},
      // Depth Anything: 1e-4 / 1e-4 measured best of lr 4e-5, 1e-4, 4e-4 and lambda 1e-4, 0.1 on
      // the demo scene with random ViT-S weights (a smoke test: README, "Depth Anything V2").
      {"depth_anything_v2", &make_depth_anything<&DepthAnythingConfig::vits>,
       DepthOutputKind::inverse_depth, 14, 1e-4, 1e-4,
       "Depth Anything V2 ViT-S, DINOv2 encoder + DPT head (affine-invariant inverse depth)",
       /*affine_disparity=*/true},
      {"depth_anything_v2_vitb", &make_depth_anything<&DepthAnythingConfig::vitb>,
       DepthOutputKind::inverse_depth, 14, 1e-4, 1e-4,
       "Depth Anything V2 ViT-B (97.5 M parameters)",
       /*affine_disparity=*/true},
      {"depth_anything_v2_vitl", &make_depth_anything<&DepthAnythingConfig::vitl>,
       DepthOutputKind::inverse_depth, 14, 1e-4, 1e-4,
       "Depth Anything V2 ViT-L (335.3 M parameters)",
       /*affine_disparity=*/true},
  };
  return table;
}

const DepthNetArchitecture& depth_net_architecture(const std::string& name) {
  std::string names;
  for (const DepthNetArchitecture& a : depth_net_architectures()) {
    if (a.name == name) return a;
    names += (names.empty() ? "" : ", ") + a.name;
  }
  fail(ErrorCategory::unsupported, "unknown depth network architecture '{}' (available: {})", name,
       names);
}

std::vector<std::string> depth_net_archs() {
  std::vector<std::string> names;
  for (const DepthNetArchitecture& a : depth_net_architectures()) names.push_back(a.name);
  return names;
}

std::unique_ptr<DepthNet> create_depth_net(const std::string& arch, double width, Generator& gen) {
  return depth_net_architecture(arch).create(width, gen);
}

}  // namespace cvd
