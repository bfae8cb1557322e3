#include "pipeline/run/quality_preset.h"

#include "engine/error.h"

namespace cvd {

const std::vector<QualityPreset>& quality_presets() {
  // Measured on the 7-Scenes kitchen (40 frames, 640x480, COLMAP poses, 2 cores): README,
  // "Quality presets".
  static const std::vector<QualityPreset> presets = {
      {"fast", 192, 0.125, 4, 60, "192 px depth, width 1/8, 4 epochs: a first look, ~3 s a frame"},
      {"default", 256, 0.125, 16, 100, "256 px depth, width 1/8, 16 epochs: ~11 s a frame"},
      {"best", 256, 0.25, 16, 100, "256 px depth, width 1/4, 16 epochs: ~2x the default's time"},
  };
  return presets;
}

const QualityPreset& quality_preset(std::string_view name) {
  std::string known;
  for (const QualityPreset& p : quality_presets()) {
    if (p.name == name) return p;
    known += (known.empty() ? "" : ", ") + p.name;
  }
  fail(ErrorCategory::invalid_argument, "unknown quality preset '{}' (expected {})", name, known);
}

}  // namespace cvd
