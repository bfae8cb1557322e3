// End-point error of a dense flow against ground truth (Middlebury / MPI-Sintel metric).
#pragma once
#include <opencv2/core.hpp>

#include <cstddef>

namespace cvd {

struct EndpointError {
  double mean = 0;                // mean |F(x) - F_gt(x)|_2 over the counted pixels
  double fraction_above_3px = 0;  // share of counted pixels with error > 3 px
  std::size_t pixels = 0;         // pixels counted
};

// Counts pixels where `mask` (CV_8U, optional: empty = all) is non-zero and the ground truth is
// known (finite, |u|,|v| < 1e9, the Middlebury "unknown" convention). A non-finite estimate counts
// as an infinite error. Flows are CV_32FC2 of the same size. Throws when no pixel is counted.
EndpointError endpoint_error(const cv::Mat& flow, const cv::Mat& ground_truth,
                             const cv::Mat& mask = cv::Mat());

}  // namespace cvd
