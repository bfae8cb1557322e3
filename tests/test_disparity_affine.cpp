// The scale-and-shift fit of affine-invariant disparity (pipeline/geometry/disparity_affine.h):
// exact samples give the exact affine; gross outliers and noise do not move it beyond what the
// inliers allow; a degenerate set falls back to scale only; no usable sample is an error.
#include <gtest/gtest.h>

#include <cmath>

#include "engine/error.h"
#include "engine/random.h"
#include "pipeline/geometry/disparity_affine.h"

namespace cvd {
namespace {

TEST(DisparityAffine, ExactSamplesGiveTheAffine) {
  std::vector<double> raw, depth;
  for (int i = 0; i < 50; ++i) {
    raw.push_back(0.1 + 0.05 * i);
    depth.push_back(1.0 / (2.5 * raw.back() + 0.3));
  }
  const DisparityAffineFit f = fit_disparity_affine(raw, depth);
  EXPECT_NEAR(f.scale, 2.5, 1e-9);
  EXPECT_NEAR(f.shift, 0.3, 1e-9);
  EXPECT_EQ(f.samples, 50);
  EXPECT_EQ(f.inliers, 50);
  EXPECT_FALSE(f.scale_only);
  EXPECT_GT(f.floor, 0.0);
}

TEST(DisparityAffine, OutliersAndNoiseDoNotMoveIt) {
  Generator gen(4);
  std::vector<double> raw, depth;
  for (int i = 0; i < 400; ++i) {
    const double r = 0.2 + 2.0 * gen.uniform();
    double d = 1.0 / (0.8 * r - 0.1);
    d *= 1.0 + 0.01 * gen.normal();                // 1% depth noise
    if (i % 5 == 0) d *= 0.3 + 3 * gen.uniform();  // 20% gross outliers
    raw.push_back(r);
    depth.push_back(d);
  }
  // Invalid samples are skipped.
  raw.push_back(-1.0);
  depth.push_back(2.0);
  raw.push_back(1.0);
  depth.push_back(0.0);
  const DisparityAffineFit f = fit_disparity_affine(raw, depth);
  EXPECT_EQ(f.samples, 400);
  EXPECT_NEAR(f.scale, 0.8, 0.02);
  EXPECT_NEAR(f.shift, -0.1, 0.02);
  EXPECT_GT(f.inliers, 280);
  // Plain least squares is pulled far off by the outliers: the robust fit is what helps.
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (int i = 0; i < 400; ++i) {
    sx += raw[i];
    sy += 1 / depth[i];
    sxx += raw[i] * raw[i];
    sxy += raw[i] / depth[i];
  }
  const double ls = (400 * sxy - sx * sy) / (400 * sxx - sx * sx);
  EXPECT_GT(std::abs(ls - 0.8), 3 * std::abs(f.scale - 0.8));
}

TEST(DisparityAffine, DegenerateSamplesFitTheScaleOnly) {
  // Every sample at one raw value: no slope can be fitted.
  const DisparityAffineFit f = fit_disparity_affine({0.5, 0.5, 0.5}, {2.0, 2.0, 2.0});
  EXPECT_TRUE(f.scale_only);
  EXPECT_NEAR(f.scale, 1.0, 1e-12);  // (1 / 2) / 0.5
  EXPECT_EQ(f.shift, 0.0);
  // A negative slope (depth growing with the network's disparity) is not a calibration either.
  const DisparityAffineFit g = fit_disparity_affine({0.1, 0.2, 0.3, 0.4}, {1.0, 2.0, 3.0, 4.0});
  EXPECT_TRUE(g.scale_only);
  EXPECT_GT(g.scale, 0.0);
}

TEST(DisparityAffine, NoUsableSampleIsANumericalError) {
  try {
    fit_disparity_affine({0.0, -1.0}, {1.0, 2.0});
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), ErrorCategory::numerical);
  }
  EXPECT_THROW(fit_disparity_affine({1.0}, {1.0, 2.0}), Error);
}

}  // namespace
}  // namespace cvd
