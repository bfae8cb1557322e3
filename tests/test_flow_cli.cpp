// The `cvd flow` subcommand: outputs, ground-truth EPE printing, and its error handling.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "pipeline/flow/flow_epe.h"
#include "pipeline/io/flow_io.h"
#include "tests/flow_test_images.h"
#include "tests/test_support.h"

namespace cvd {
namespace {

using test::constant_flow;
using test::TempDir;
using test::textured_image;

double mean_epe(const cv::Mat& a, const cv::Mat& b, cv::Rect region) {
  cv::Mat mask = cv::Mat::zeros(a.size(), CV_8U);
  mask(region).setTo(255);
  return endpoint_error(a, b, mask).mean;
}

void write_bytes(const std::filesystem::path& p, const std::vector<char>& bytes) {
  std::ofstream out(p, std::ios::binary);
  out.write(bytes.data(), std::streamsize(bytes.size()));
}

class FlowCli : public ::testing::Test {
 protected:
  void SetUp() override {
    a_ = dir_ / "a.png";
    b_ = dir_ / "b.png";
    const cv::Mat a = textured_image({160, 120}, 9);
    cv::Mat b;
    cv::warpAffine(a, b, cv::Matx23d(1, 0, 2, 0, 1, 1), a.size());
    cv::imwrite(a_.string(), a);
    cv::imwrite(b_.string(), b);
  }
  TempDir dir_;
  std::filesystem::path a_, b_;
};

TEST_F(FlowCli, WritesFlowMaskVisualisationAndBackwardFlow) {
  const auto r =
      test::run_cvd(fmt::format("flow {} {} -o {} --vis {} --mask {} --backward {}", a_.string(),
                                b_.string(), (dir_ / "f.flo").string(), (dir_ / "v.png").string(),
                                (dir_ / "m.png").string(), (dir_ / "bw.flo").string()));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const cv::Mat f = read_flo(dir_ / "f.flo");
  EXPECT_EQ(f.size(), cv::Size(160, 120));
  EXPECT_LT(mean_epe(f, constant_flow(f.size(), 2, 1), cv::Rect(16, 16, 128, 88)), 0.25);
  EXPECT_EQ(read_flo(dir_ / "bw.flo").size(), cv::Size(160, 120));
  const cv::Mat m = cv::imread((dir_ / "m.png").string(), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(m.type(), CV_8U);
  EXPECT_GT(cv::countNonZero(m), 160 * 120 / 2);
  EXPECT_EQ(cv::imread((dir_ / "v.png").string()).size(), cv::Size(160, 120));
}

TEST_F(FlowCli, PrintsTheEndpointErrorAgainstGroundTruth) {
  write_flo(dir_ / "gt.flo", constant_flow({160, 120}, 2, 1));
  const auto r = test::run_cvd(fmt::format("flow {} {} -o {} --gt {}", a_.string(), b_.string(),
                                           (dir_ / "f.flo").string(), (dir_ / "gt.flo").string()));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("epe_all "), std::string::npos) << r.output;
}

TEST_F(FlowCli, MissingImageIsAnIoErrorNamingTheFile) {
  const auto r = test::run_cvd(fmt::format("flow {} {} -o {}", (dir_ / "nope.png").string(),
                                           b_.string(), (dir_ / "f.flo").string()));
  EXPECT_EQ(r.exit_code, 4) << r.output;  // kExitIo
  EXPECT_NE(r.output.find("nope.png"), std::string::npos) << r.output;
  EXPECT_FALSE(std::filesystem::exists(dir_ / "f.flo"));
}

TEST_F(FlowCli, UndecodableImageIsABadInputNamingTheFile) {
  write_bytes(dir_ / "junk.png", {'n', 'o', 't', ' ', 'a', ' ', 'p', 'n', 'g'});
  const auto r = test::run_cvd(fmt::format(
      "flow {} {} -o {}", a_.string(), (dir_ / "junk.png").string(), (dir_ / "f.flo").string()));
  EXPECT_EQ(r.exit_code, 3) << r.output;  // kExitBadInput
  EXPECT_NE(r.output.find("junk.png"), std::string::npos) << r.output;
}

TEST_F(FlowCli, SizeMismatchIsABadInputNamingBothFiles) {
  cv::imwrite((dir_ / "small.png").string(), textured_image({80, 60}, 10));
  const auto r = test::run_cvd(fmt::format(
      "flow {} {} -o {}", a_.string(), (dir_ / "small.png").string(), (dir_ / "f.flo").string()));
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("small.png"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("a.png"), std::string::npos) << r.output;
}

TEST_F(FlowCli, RejectsUnknownPresetAndMethod) {
  auto r = test::run_cvd(fmt::format("flow {} {} -o {} --preset slow", a_.string(), b_.string(),
                                     (dir_ / "f.flo").string()));
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("slow"), std::string::npos) << r.output;
  r = test::run_cvd(fmt::format("flow {} {} -o {} --method flownet2", a_.string(), b_.string(),
                                (dir_ / "f.flo").string()));
  EXPECT_EQ(r.exit_code, 3) << r.output;  // FlowNet2 needs --model (no weights ship)
  EXPECT_NE(r.output.find("--model"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace cvd
