#include "pipeline/flow/flow_pair.h"

#include <cmath>

#include "engine/error.h"

namespace cvd {

FlowPairResult compute_pair_flow(OpticalFlow& estimator, const cv::Mat& img_i, const cv::Mat& img_j,
                                 const FlowPairOptions& options, const ImageKeypoints* keypoints_i,
                                 const ImageKeypoints* keypoints_j) {
  CVD_CHECK(!img_i.empty() && !img_j.empty(), "compute_pair_flow: an image is empty");
  CVD_CHECK(img_i.size() == img_j.size(), "compute_pair_flow: image sizes differ ({}x{} vs {}x{})",
            img_i.cols, img_i.rows, img_j.cols, img_j.rows);
  CVD_CHECK(img_i.type() == CV_8UC3 && img_j.type() == CV_8UC3,
            "compute_pair_flow: images must be 8-bit BGR (CV_8UC3)");
  FlowPairResult r;
  if (options.homography_prewarp) {
    const ImageKeypoints ki =
        keypoints_i ? *keypoints_i : detect_keypoints(img_i, options.homography);
    const ImageKeypoints kj =
        keypoints_j ? *keypoints_j : detect_keypoints(img_j, options.homography);
    r.homography = estimate_homography(ki, kj, options.homography);
  } else {
    r.homography.reason = "homography pre-warp disabled";
  }
  const cv::Matx33d g = r.homography.a_to_b;
  if (r.homography.identity_fallback) {
    r.forward = estimator.estimate(img_i, img_j);
    r.backward = estimator.estimate(img_j, img_i);
  } else {
    r.forward = flow_through_homography(estimator, img_i, img_j, g);
    cv::Matx33d g_inv = g.inv();
    if (std::abs(g_inv(2, 2)) > 1e-12) g_inv *= 1.0 / g_inv(2, 2);
    r.backward = flow_through_homography(estimator, img_j, img_i, g_inv);
  }
  r.forward_mask = forward_backward_mask(r.forward, r.backward, options.fb_threshold_px);
  r.backward_mask = forward_backward_mask(r.backward, r.forward, options.fb_threshold_px);
  r.forward_valid_fraction = valid_fraction(r.forward_mask);
  r.backward_valid_fraction = valid_fraction(r.backward_mask);
  return r;
}

}  // namespace cvd
