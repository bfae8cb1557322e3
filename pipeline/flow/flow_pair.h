// Optical flow of one frame pair in both directions, with forward-backward validity masks: the unit
// of work of the pipeline's flow stage (paper section 5; caching is the caller's business).
#pragma once
#include <opencv2/core.hpp>

#include "pipeline/flow/flow_consistency.h"
#include "pipeline/flow/flow_homography.h"
#include "pipeline/flow/optical_flow.h"

namespace cvd {

struct FlowPairOptions {
  bool homography_prewarp = true;  // align with a homography before the estimator [on]
  HomographyOptions homography;
  float fb_threshold_px = kDefaultFbThresholdPx;  // forward-backward threshold [1 px]
};

struct FlowPairResult {
  cv::Mat forward;        // i -> j, CV_32FC2, pixels
  cv::Mat backward;       // j -> i
  cv::Mat forward_mask;   // CV_8U, 255 = consistent (valid) pixel of frame i
  cv::Mat backward_mask;  // CV_8U, 255 = consistent pixel of frame j
  double forward_valid_fraction = 0;
  double backward_valid_fraction = 0;
  // G (i -> j); the backward direction uses G^-1. Identity with identity_fallback when the
  // pre-warp is off or failed.
  HomographyEstimate homography;

  // The reference implementation keeps a pair only when BOTH directions keep >= 20% [0.2].
  bool both_directions_keep(double min_fraction) const {
    return forward_valid_fraction >= min_fraction && backward_valid_fraction >= min_fraction;
  }
};

// Flow i -> j and j -> i of two 8-bit BGR images of the same size, each optionally through the
// homography pre-warp (one homography estimate, inverted for the backward direction), and the
// forward-backward masks of both. Keypoints detected beforehand (detect_keypoints with
// options.homography) may be passed to avoid detecting them again for every pair a frame is in.
// Throws Error(invalid_argument) for mismatched or empty images.
FlowPairResult compute_pair_flow(OpticalFlow& estimator, const cv::Mat& img_i, const cv::Mat& img_j,
                                 const FlowPairOptions& options = {},
                                 const ImageKeypoints* keypoints_i = nullptr,
                                 const ImageKeypoints* keypoints_j = nullptr);

}  // namespace cvd
