// How the flow stage holds its pairs (pipeline/run/run_stages.h, issue 19): flows kept in memory
// in half precision come back as CV_32FC2 within half-precision rounding of the computed flow;
// a pair left in the cache (streamed) is rounded the same way when read, so both storages give
// training the same numbers; with half precision off the cached flow comes back exactly.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>

#include "engine/random.h"
#include "pipeline/io/flow_io.h"
#include "pipeline/run/run_stages.h"

namespace cvd {
namespace {

namespace fs = std::filesystem;

cv::Mat random_flow(int w, int h, uint64_t seed) {
  Generator g(seed);
  cv::Mat f(h, w, CV_32FC2);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      f.at<cv::Vec2f>(y, x) = {static_cast<float>(60.0 * (g.uniform() - 0.5)),
                               static_cast<float>(20.0 * (g.uniform() - 0.5))};
  return f;
}

double max_difference(const cv::Mat& a, const cv::Mat& b) { return cv::norm(a, b, cv::NORM_INF); }

TEST(FlowStageStorage, HalfPrecisionIsTheSameForHeldAndCachedPairsAndCloseToTheFlow) {
  const fs::path dir = fs::temp_directory_path() / "cvd_test_flow_stage_storage";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const cv::Mat fwd = random_flow(37, 23, 1), bwd = random_flow(37, 23, 2);
  const cv::Mat mask(23, 37, CV_8U, cv::Scalar(255));
  write_flo(dir / "a__b.fwd.flo", fwd);
  write_flo(dir / "a__b.bwd.flo", bwd);
  ASSERT_TRUE(cv::imwrite((dir / "a__b.fwd_mask.png").string(), mask));
  ASSERT_TRUE(cv::imwrite((dir / "a__b.bwd_mask.png").string(), mask));

  FlowPairData held;
  held.pair = {0, 2};
  held.stem = "a__b";
  held.kept = true;
  fwd.convertTo(held.forward, CV_16F);
  bwd.convertTo(held.backward, CV_16F);
  held.forward_mask = held.backward_mask = mask;
  FlowPairData cached = held;
  cached.forward = cached.backward = cv::Mat();

  FlowStage stage;
  stage.dir = dir;
  stage.pairs = {held, cached};
  for (bool half : {true, false}) {
    stage.half_precision = half;
    const FlowPairData a = stage.load(0), b = stage.load(1);
    for (const cv::Mat* m : {&a.forward, &a.backward, &b.forward, &b.backward})
      ASSERT_EQ(m->type(), CV_32FC2);
    // Half precision keeps 11 significant bits: |error| <= 2^-11 |flow| <= 30 / 2048 px.
    EXPECT_LE(max_difference(a.forward, fwd), 30.0 / 2048);
    EXPECT_GT(max_difference(a.forward, fwd), 0.0) << "held flows are half precision";
    if (half) {
      EXPECT_EQ(max_difference(b.forward, a.forward), 0.0);
      EXPECT_EQ(max_difference(b.backward, a.backward), 0.0);
    } else {
      EXPECT_EQ(max_difference(b.forward, fwd), 0.0);
      EXPECT_EQ(max_difference(b.backward, bwd), 0.0);
    }
    EXPECT_EQ(cv::countNonZero(b.forward_mask), 23 * 37);
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace cvd
