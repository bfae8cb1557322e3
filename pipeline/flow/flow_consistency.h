// Forward-backward consistency of a pair of dense flows (paper section 5): a pixel x of image a is
// valid when following F_ab to b and F_ba back lands within `threshold_px` of x.
#pragma once
#include <opencv2/core.hpp>

namespace cvd {

// Default forward-backward threshold in pixels [1 px in the reference implementation].
inline constexpr float kDefaultFbThresholdPx = 1.0f;

// CV_8U mask of a's size: 255 where
//   x + F_ab(x) lies inside b (0 <= u <= w-1, 0 <= v <= h-1), both flows are finite there, and
//   |F_ab(x) + F_ba(x + F_ab(x))|_2 <= threshold_px   (F_ba sampled bilinearly),
// 0 elsewhere. Both flows are CV_32FC2 of the same size.
cv::Mat forward_backward_mask(const cv::Mat& flow_ab, const cv::Mat& flow_ba,
                              float threshold_px = kDefaultFbThresholdPx);

// Fraction of non-zero pixels of a CV_8U mask, in [0, 1] (0 for an empty mask).
double valid_fraction(const cv::Mat& mask);

}  // namespace cvd
