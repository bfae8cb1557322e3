// User masks (--masks, 0 = ignore): loading and resizing without shrinking ignored regions,
// clearing flow-pair pixels on either end of a flow vector, and the pipeline's use of them
// (run.json counts, early error for a missing folder, a corrupt mask named).
#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "engine/error.h"
#include "pipeline/flow/user_masks.h"
#include "tests/test_support.h"

namespace cvd::test {
namespace {

namespace fs = std::filesystem;

TEST(UserMasks, MissingFolderIsAnIoErrorNamingIt) {
  try {
    load_user_masks("/nonexistent/masks", {"a"}, {4, 4});
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), ErrorCategory::io);
    EXPECT_NE(std::string(e.what()).find("/nonexistent/masks"), std::string::npos) << e.what();
  }
}

TEST(UserMasks, FramesWithoutAFileAreUsableAndAnyNonZeroValueIsUsable) {
  TempDir dir;
  cv::Mat m(4, 6, CV_8U, cv::Scalar(1));  // 1 = usable (COLMAP: only 0 is ignored)
  m.at<uint8_t>(2, 3) = 0;
  ASSERT_TRUE(cv::imwrite((dir.path() / "b.png").string(), m));
  int found = -1;
  auto masks = load_user_masks(dir.path(), {"a", "b"}, {6, 4}, &found);
  EXPECT_EQ(found, 1);
  ASSERT_EQ(masks.size(), 2u);
  EXPECT_EQ(cv::countNonZero(masks[0]), 24);
  EXPECT_EQ(cv::countNonZero(masks[1]), 23);
  EXPECT_EQ(masks[1].at<uint8_t>(2, 3), 0);
  EXPECT_EQ(masks[1].at<uint8_t>(0, 0), 255);
}

TEST(UserMasks, DownsizingNeverShrinksAnIgnoredRegion) {
  TempDir dir;
  cv::Mat m(8, 8, CV_8U, cv::Scalar(255));
  m.at<uint8_t>(5, 6) = 0;  // one ignored input pixel
  ASSERT_TRUE(cv::imwrite((dir.path() / "a.png").string(), m));
  auto masks = load_user_masks(dir.path(), {"a"}, {4, 4});
  ASSERT_EQ(masks[0].size(), cv::Size(4, 4));
  EXPECT_EQ(masks[0].at<uint8_t>(2, 3), 0);  // the 2x2 block holding (5, 6)
  EXPECT_EQ(cv::countNonZero(masks[0]), 15);
}

TEST(UserMasks, CorruptFileIsAFormatErrorNamingIt) {
  TempDir dir;
  std::ofstream(dir.path() / "a.png") << "not a png";
  try {
    load_user_masks(dir.path(), {"a"}, {4, 4});
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), ErrorCategory::format);
    EXPECT_NE(std::string(e.what()).find("a.png"), std::string::npos) << e.what();
  }
}

TEST(UserMasks, ClearsSourcePixelsAndPixelsWhoseBilinearTargetTouchesAnIgnoredPixel) {
  const int w = 10, h = 6;
  cv::Mat flow(h, w, CV_32FC2, cv::Scalar(1.5f, 0.0f));
  cv::Mat valid(h, w, CV_8U, cv::Scalar(255));
  cv::Mat ua(h, w, CV_8U, cv::Scalar(255)), ub(h, w, CV_8U, cv::Scalar(255));
  ua.at<uint8_t>(0, 0) = 0;
  ub.at<uint8_t>(3, 5) = 0;
  valid.at<uint8_t>(5, 9) = 0;  // already invalid: not counted again
  const long long cleared = apply_user_masks(valid, flow, ua, ub);
  // Source: (0,0). Targets x + 1.5 read columns floor and floor + 1, rows y and y + 1 (flow v = 0
  // lands exactly on row y, whose neighbour y + 1 is read with weight 0 but still read): pixel
  // (3, 5) of b is touched from x in {3, 4} on rows {2, 3}.
  EXPECT_EQ(valid.at<uint8_t>(0, 0), 0);
  for (int y : {2, 3})
    for (int x : {3, 4}) EXPECT_EQ(valid.at<uint8_t>(y, x), 0) << y << "," << x;
  EXPECT_EQ(valid.at<uint8_t>(3, 2), 255);
  EXPECT_EQ(valid.at<uint8_t>(3, 5), 255);
  EXPECT_EQ(valid.at<uint8_t>(4, 3), 255);
  EXPECT_EQ(cleared, 5);
  EXPECT_EQ(cv::countNonZero(valid), w * h - 6);
}

TEST(UserMasks, SizeMismatchIsRejected) {
  cv::Mat flow(4, 4, CV_32FC2, cv::Scalar(0, 0)), valid(4, 4, CV_8U, cv::Scalar(255));
  cv::Mat small(3, 4, CV_8U, cv::Scalar(255));
  EXPECT_THROW(apply_user_masks(valid, flow, small, valid.clone()), Error);
}

// `cvd run` with masks: counted in run.json; a missing folder fails before any output exists.
TEST(UserMasksCli, RunLeavesMaskedPixelsOutAndRecordsIt) {
  TempDir dir;
  CommandResult r = run_cvd("scene --out '" + (dir.path() / "scene").string() +
                            "' --frames 4 --width 96 --height 64");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  fs::path masks = dir.path() / "masks";
  fs::create_directories(masks);
  cv::Mat m(64, 96, CV_8U, cv::Scalar(255));
  m.colRange(0, 48).setTo(0);  // ignore the left half of two frames
  for (const char* name : {"frame_000000", "frame_000002"})
    ASSERT_TRUE(cv::imwrite((masks / (std::string(name) + ".png")).string(), m));
  const std::string intr = intrinsics_flag_value(dir.path() / "scene" / "intrinsics.json");
  const std::string common = "run '" + (dir.path() / "scene" / "rgb").string() +
                             "' --epochs 1 --warmup 1 --width 0.0625 --depth-size 64 --no-videos "
                             "--no-ply --poses '" +
                             (dir.path() / "scene" / "poses.txt").string() +
                             "' --poses-format tum --intrinsics " + intr;
  fs::path out = dir.path() / "out";
  r = run_cvd(common + " -o '" + out.string() + "' --masks '" + masks.string() + "'");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::ifstream rf(out / "run.json");
  auto info = nlohmann::json::parse(rf);
  EXPECT_EQ(info["user_masks"]["frames_with_masks"], 2);
  EXPECT_GT(info["user_masks"]["flow_pixels_cleared"].get<long long>(), 0);

  fs::path out2 = dir.path() / "out2";
  r = run_cvd(common + " -o '" + out2.string() + "' --masks '" + (dir.path() / "nope").string() +
              "'");
  EXPECT_EQ(r.exit_code, 4) << r.output;
  EXPECT_NE(r.output.find("masks folder not found"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(out2)) << "output created before the masks were checked";
}

}  // namespace
}  // namespace cvd::test
