// The `--quality` presets: the four knobs that set what a run costs (depth resolution, width of the
// default network, epochs, sparse warm-up steps), chosen together so a user picks a cost, not four
// numbers. Flags given explicitly override the preset's value for that knob.
#pragma once
#include <string>
#include <string_view>
#include <vector>

namespace cvd {

struct QualityPreset {
  std::string name;
  int depth_long_side = 0;  // --depth-size
  double width = 0;         // --width (default network only)
  int epochs = 0;           // --epochs
  int warmup_steps = 0;     // --warmup (default network only)
  std::string summary;      // one line for --help: what it is for and what it costs
};

// fast, default, best; RunOptions' defaults are the "default" preset's values.
const std::vector<QualityPreset>& quality_presets();

// The preset called `name`; throws Error(invalid_argument) naming the known ones otherwise.
const QualityPreset& quality_preset(std::string_view name);

}  // namespace cvd
