// What the command line tells a user before any run: every --help shows each flag's default (the
// cost knobs: the --quality preset's), and
// --version lists the backends and the libraries and programs found.
#include <gtest/gtest.h>

#include <fmt/format.h>

#include "pipeline/poses/colmap_runner.h"
#include "pipeline/run/quality_preset.h"
#include "test_support.h"

namespace cvd {
namespace {

using test::run_cvd;

TEST(CliHelp, RunHelpShowsEveryDefault) {
  const test::CommandResult r = run_cvd("run --help");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // The cost knobs show the "default" quality preset's values.
  const QualityPreset& q = quality_preset("default");
  for (const std::string& shown :
       {fmt::format("--epochs INT={}", q.epochs),
        fmt::format("--depth-size INT={}", q.depth_long_side),
        fmt::format("--width FLOAT={:g}", q.width), fmt::format("--warmup INT={}", q.warmup_steps),
        std::string("--quality TEXT:{fast,default,best}=default"), std::string("=mannequin"),
        std::string("--formats"), std::string("=[pfm,png16,color]"),
        std::string("mannequin 0.0004")})
    EXPECT_NE(r.output.find(shown), std::string::npos) << shown << " missing in:\n" << r.output;
}

TEST(CliHelp, VersionListsBackendsAndDependencies) {
  const test::CommandResult r = run_cvd("--version");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* shown : {"compiled backends:", "reference (f64, cpu)", "oneDNN",
                            "dependencies:", "OpenCV 4.", "libavformat "})
    EXPECT_NE(r.output.find(shown), std::string::npos) << shown << " missing in:\n" << r.output;
  // COLMAP: its version and path when it is installed, else a line saying it was not found.
  if (find_executable("colmap").empty())
    EXPECT_NE(r.output.find("COLMAP: not found"), std::string::npos) << r.output;
  else
    EXPECT_NE(r.output.find("COLMAP 3."), std::string::npos) << r.output;
}

}  // namespace
}  // namespace cvd
