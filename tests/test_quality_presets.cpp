// `--quality` (pipeline/run/quality_preset.h): a preset sets the four cost knobs of a run, and a
// knob given as a flag keeps the flag's value.
#include <gtest/gtest.h>

#include <fmt/format.h>

#include <algorithm>
#include <nlohmann/json.hpp>
#include <string>

#include "engine/error.h"
#include "pipeline/run/quality_preset.h"
#include "pipeline/run/run_options.h"
#include "tests/run_output_compare.h"
#include "tests/test_support.h"

namespace cvd::test {
namespace {

namespace fs = std::filesystem;

TEST(QualityPreset, DefaultIsWhatRunOptionsStartWithAndUnknownNamesAreRejected) {
  const RunOptions o;
  const QualityPreset& d = quality_preset("default");
  EXPECT_EQ(o.depth_long_side, d.depth_long_side);
  EXPECT_EQ(o.width, d.width);
  EXPECT_EQ(o.epochs, d.epochs);
  EXPECT_EQ(o.warmup_steps, d.warmup_steps);
  ASSERT_EQ(quality_presets().size(), 3u);
  EXPECT_EQ(quality_presets()[0].name, "fast");
  EXPECT_EQ(quality_presets()[2].name, "best");
  try {
    quality_preset("Fast");
    ADD_FAILURE() << "preset names are exact";
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), ErrorCategory::invalid_argument);
    EXPECT_NE(std::string(e.what()).find("fast, default, best"), std::string::npos) << e.what();
  }
}

TEST(QualityPreset, CliAppliesThePresetToTheKnobsNotGiven) {
  TempDir t;
  const fs::path scene = t / "scene";
  CommandResult r =
      run_cvd("scene --out " + shell_quoted(scene) + " --frames 4 --width 96 --height 72");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string intr = intrinsics_flag_value(scene / "intrinsics.json");
  // fast: its depth size (differs from the default preset's); width, epochs, warm-up given.
  const QualityPreset& fast = quality_preset("fast");
  ASSERT_NE(fast.depth_long_side, quality_preset("default").depth_long_side);
  r = run_cvd("run " + shell_quoted(scene / "rgb") + " -o " + shell_quoted(t / "out") +
              " --quality fast --width 0.0625 --epochs 1 --warmup 1 --no-videos --no-ply --poses " +
              shell_quoted(scene / "poses.txt") + " --poses-format tum --intrinsics " + intr);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json info = read_json(t / "out" / "run.json");
  const auto size = info["depth_size"].get<std::vector<int>>();
  EXPECT_EQ(std::max(size[0], size[1]), fast.depth_long_side) << info["depth_size"];
  EXPECT_EQ(info["training"]["epochs"].get<int>(), 1) << "--epochs given: the preset's ignored";
  EXPECT_NE(info["network"].get<std::string>().find("0.0625"), std::string::npos)
      << info["network"];
  // run.json also says what the run cost: per-stage times and peak memory.
  EXPECT_GT(info["timings_s"]["total"].get<double>(), 0.0);
  EXPECT_GT(info["timings_s"]["loss_evaluation"].get<double>(), 0.0);
  EXPECT_LE(info["timings_s"]["training"].get<double>() +
                info["timings_s"]["loss_evaluation"].get<double>(),
            info["timings_s"]["total"].get<double>());
  EXPECT_EQ(info["training"]["geometric_loss_pairs"].get<int>(), info["pairs"]["kept"].get<int>())
      << "fewer pairs than the cap: the loss is evaluated on all of them";
  EXPECT_GT(info["peak_rss_mb"]["process"].get<double>(), 10.0) << info["peak_rss_mb"];
  EXPECT_LT(info["peak_rss_mb"]["process"].get<double>(), 4096.0) << info["peak_rss_mb"];
}

}  // namespace
}  // namespace cvd::test
