// The focal length from a video container's metadata (issue 11, pipeline/poses/container_focal.h):
// the key matching, reading a .mov / .mp4 written by ffmpeg with the QuickTime key iPhones use,
// and `cvd run` on such a video taking its intrinsics from it (source recorded in run.json).
// The file tests need the `ffmpeg` binary to write the videos and skip, saying so, without it.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>

#include "pipeline/poses/colmap_runner.h"
#include "pipeline/poses/container_focal.h"
#include "pipeline/poses/exif_focal.h"
#include "tests/test_support.h"

namespace cvd {
namespace {

namespace fs = std::filesystem;
using test::CommandResult;
using test::run_command;
using test::shell_quoted;
using test::TempDir;
using json = nlohmann::json;

const char* kAppleKey = "com.apple.quicktime.camera.focal_length.35mm_equivalent";

#define CVD_REQUIRE_FFMPEG()                                                                  \
  if (find_executable("ffmpeg").empty()) {                                                    \
    GTEST_SKIP() << "ffmpeg is not on PATH (Debian: apt install ffmpeg); it writes the test " \
                    "videos";                                                                 \
  }

TEST(ContainerFocal, ReadsTheFirstFocal35mmKeyOfTheMetadata) {
  auto f = focal_35mm_from_metadata(
      {{"major_brand", "qt  "}, {"encoder", "Lavf"}, {kAppleKey, "26"}, {"focal_35mm", "99"}});
  ASSERT_TRUE(f.has_value());
  EXPECT_DOUBLE_EQ(f->focal_35mm, 26.0);
  EXPECT_EQ(f->key, kAppleKey);
  // Other spellings, with units after the number.
  f = focal_35mm_from_metadata({{"FocalLengthIn35mmFormat", "28.5 mm"}});
  ASSERT_TRUE(f.has_value());
  EXPECT_DOUBLE_EQ(f->focal_35mm, 28.5);
}

TEST(ContainerFocal, IgnoresOtherKeysAndValuesThatAreNotAPlausibleFocal) {
  EXPECT_FALSE(focal_35mm_from_metadata({}).has_value());
  // A real focal (not 35 mm equivalent) and a lens model string are not used.
  EXPECT_FALSE(focal_35mm_from_metadata(
                   {{"com.apple.quicktime.camera.focal_length", "4.2"},
                    {"com.apple.quicktime.camera.lens_model", "iPhone 12 back camera 4.2mm f/1.6"}})
                   .has_value());
  for (const char* bad : {"", "unknown", "0", "-26", "1e9", "nan"})
    EXPECT_FALSE(focal_35mm_from_metadata({{kAppleKey, bad}}).has_value()) << bad;
  // A bad value does not hide a good one under another matching key.
  auto f = focal_35mm_from_metadata({{kAppleKey, "0"}, {"focal_length_35mm", "24"}});
  ASSERT_TRUE(f.has_value());
  EXPECT_DOUBLE_EQ(f->focal_35mm, 24.0);
}

TEST(ContainerFocal, UnreadableFilesHaveNoMetadata) {
  TempDir dir;
  EXPECT_TRUE(read_container_metadata(dir / "missing.mov").empty());
  std::ofstream(dir / "junk.mp4") << "not a video at all";
  EXPECT_FALSE(read_container_focal_35mm(dir / "junk.mp4").has_value());
}

// Writes a 4-frame test video with `tags` (key=value) as container metadata.
CommandResult write_video(const fs::path& out, const std::vector<std::string>& tags,
                          const std::string& input = "-f lavfi -i testsrc=size=64x48:rate=5") {
  std::string cmd = "ffmpeg -v error -y " + input + " -frames:v 4 -c:v mpeg4 -q:v 2";
  cmd += " -movflags use_metadata_tags";
  for (const auto& t : tags) cmd += " -metadata '" + t + "'";
  return run_command(cmd + " " + shell_quoted(out));
}

TEST(ContainerFocal, ReadsTheQuickTimeKeyFromMovAndMp4Files) {
  CVD_REQUIRE_FFMPEG();
  TempDir dir;
  for (const char* ext : {".mov", ".mp4"}) {
    const fs::path v = dir / (std::string("clip") + ext);
    CommandResult r = write_video(v, {std::string(kAppleKey) + "=26"});
    ASSERT_EQ(r.exit_code, 0) << r.output;
    auto f = read_container_focal_35mm(v);
    ASSERT_TRUE(f.has_value()) << ext;
    EXPECT_DOUBLE_EQ(f->focal_35mm, 26.0);
    EXPECT_EQ(f->key, kAppleKey);
  }
  const fs::path plain = dir / "plain.mp4";
  CommandResult r = write_video(plain, {});
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_FALSE(read_container_focal_35mm(plain).has_value());
  EXPECT_FALSE(read_container_metadata(plain).empty());  // it has metadata, just no focal
}

// `cvd run` on a video whose container states the focal, with the generated scene's poses and
// no --intrinsics: the intrinsics come from the container, at the focal the scene was rendered
// with (the 35 mm value is written to 4 decimals, so within 0.1%), and run.json says so.
TEST(ContainerFocal, CvdRunTakesTheIntrinsicsFromTheVideoContainer) {
  CVD_REQUIRE_FFMPEG();
  TempDir dir;
  const fs::path scene = dir / "scene";
  CommandResult r =
      test::run_cvd("scene --out " + shell_quoted(scene) + " --frames 6 --width 128 --height 96");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  json k = json::parse(std::ifstream(scene / "intrinsics.json"));
  const double fx = k["fx"].get<double>();
  const double f35 = fx * std::hypot(36.0, 24.0) / std::hypot(128.0, 96.0);
  ASSERT_NEAR(focal_px_from_35mm(f35, 128, 96), fx, 1e-9 * fx);
  char value[64];
  std::snprintf(value, sizeof value, "%.4f", f35);
  // The frames are frame_000000.png ... (cvd scene); the video keeps their order.
  const fs::path video = dir / "clip.mov";
  r = write_video(video, {std::string(kAppleKey) + "=" + value},
                  "-framerate 10 -i " + shell_quoted(scene / "rgb" / "frame_%06d.png"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const fs::path out = dir / "out";
  r = test::run_cvd("run " + shell_quoted(video) + " -o " + shell_quoted(out) +
                    " --epochs 0 --warmup 1 --width 0.0625 --depth-size 64 --no-videos --no-ply"
                    " --poses " +
                    shell_quoted(scene / "poses.txt") + " --poses-format tum");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  json run = json::parse(std::ifstream(out / "run.json"));
  const json& poses = run["poses"];
  EXPECT_NE(poses["intrinsics_source"].get<std::string>().find("container"), std::string::npos)
      << poses.dump();
  const std::vector<int> dsize = run["depth_size"];
  const double fx_depth = poses["intrinsics_depth_res"][0].get<double>();
  EXPECT_NEAR(fx_depth, fx * dsize[0] / 128.0, 1e-3 * fx_depth) << poses.dump();
}

}  // namespace
}  // namespace cvd
