// What the command line tells a user before any run: every --help shows each flag's default, and
// --version lists the backends and the libraries and programs found.
#include <gtest/gtest.h>

#include "pipeline/poses/colmap_runner.h"
#include "test_support.h"

namespace cvd {
namespace {

using test::run_cvd;

TEST(CliHelp, RunHelpShowsEveryDefault) {
  const test::CommandResult r = run_cvd("run --help");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* shown :
       {"--epochs INT=20", "--depth-size INT=384", "--width FLOAT=0.25", "--warmup INT=200",
        "=mannequin", "--formats", "=[pfm,png16,color]", "mannequin 0.0004"})
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
