// Homography pre-warp for optical flow (paper section 5 / reference implementation): align b to a
// with a homography from keypoint matches, run a flow estimator on the aligned pair, and compose
// the result back so that it maps a's pixels to b's ORIGINAL pixels.
//
// Conventions. G = HomographyEstimate::a_to_b maps a's pixel coordinates to b's: x_b ~ G x_a
// (homogeneous), estimated from matches a -> b. H = G^-1 is the warp that brings b into a's frame.
//
//   aligned b:    b~(x) = b(G x)   (cv::warpPerspective(b, G, WARP_INVERSE_MAP), replicated border)
//   residual:     r = estimator(a, b~),   so a(x) ~ b~(x + r(x)) = b(G (x + r(x)))
//   composed:     f(x) = G(x + r(x)) - x  =  H^-1(x + r(x)) - x
//
// where G(p) = (G p~)_xy / (G p~)_z is the projective map. With G the identity this is just r, so
// the identity fallback returns the estimator's flow unchanged.
#pragma once
#include <opencv2/core.hpp>

#include <string>
#include <vector>

#include "pipeline/flow/optical_flow.h"

namespace cvd {

enum class KeypointDetector { sift, orb };

// "sift" | "orb"; throws Error(invalid_argument) otherwise.
KeypointDetector parse_keypoint_detector(const std::string& name);

struct HomographyOptions {
  KeypointDetector detector = KeypointDetector::sift;
  int max_features = 1000;           // per image (brute-force matching is quadratic in it)
  double lowe_ratio = 0.75;          // best / second-best descriptor distance [0.75]
  double ransac_threshold_px = 4.0;  // RANSAC reprojection threshold [4 px]
  int min_inliers = 20;              // fewer RANSAC inliers -> identity fallback
  // The image rectangle mapped by G must keep an area within [1/max_area_ratio, max_area_ratio] of
  // the original and stay convex and in front (w > 0 at all four corners); otherwise G is
  // declared degenerate -> identity fallback.
  double max_area_ratio = 4.0;
};

struct HomographyEstimate {
  cv::Matx33d a_to_b = cv::Matx33d::eye();  // G, normalised so G(2,2) = 1
  bool identity_fallback = true;            // true: a_to_b is the identity because of `reason`
  std::string reason;                       // why the fallback was taken (empty when not)
  int keypoints_a = 0, keypoints_b = 0;
  int matches = 0;  // after the ratio test
  int inliers = 0;  // RANSAC inliers
};

// Keypoints and descriptors of one image; detect once per frame and reuse them for every pair
// the frame is part of (detection dominates the cost: ~0.3-0.5 s for SIFT at 1024x436).
struct ImageKeypoints {
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
  cv::Size image_size;
  KeypointDetector detector = KeypointDetector::sift;
};
ImageKeypoints detect_keypoints(const cv::Mat& image_bgr, const HomographyOptions& options = {});

// Estimates G (a -> b) from keypoint matches; on failure returns the identity with
// identity_fallback set and the reason logged (spdlog warn). Images: 8-bit BGR or gray, same size.
HomographyEstimate estimate_homography(const cv::Mat& a_bgr, const cv::Mat& b_bgr,
                                       const HomographyOptions& options = {});
// The same from keypoints detected beforehand (same detector, same image size).
HomographyEstimate estimate_homography(const ImageKeypoints& a, const ImageKeypoints& b,
                                       const HomographyOptions& options = {});

// Why G is unusable as a pre-warp for an image of `size` ("" when usable): non-finite, a corner
// behind the camera (w <= 0), a non-convex or flipped image of the rectangle, or an area change
// beyond max_area_ratio.
std::string homography_degeneracy(const cv::Matx33d& a_to_b, cv::Size size, double max_area_ratio);

// f(x) = G(x + r(x)) - x for every pixel x of `residual` (CV_32FC2); pixels whose target has
// w <= 0 get NaN flow.
cv::Mat compose_homography_flow(const cv::Mat& residual, const cv::Matx33d& a_to_b);

// The flow of the homography itself, f(x) = G(x) - x, for an image of `size`.
cv::Mat homography_flow(const cv::Matx33d& a_to_b, cv::Size size);

// Warps b into a's frame with G (b~(x) = b(G x)), runs `estimator` on (a, b~) and composes the
// flow back. With G exactly the identity it runs the estimator on (a, b) directly.
cv::Mat flow_through_homography(OpticalFlow& estimator, const cv::Mat& a_bgr, const cv::Mat& b_bgr,
                                const cv::Matx33d& a_to_b);

// An OpticalFlow that adds the homography pre-warp around another one (not owned; it must
// outlive this object).
class HomographyPrewarpedFlow final : public OpticalFlow {
 public:
  HomographyPrewarpedFlow(OpticalFlow& inner, const HomographyOptions& options = {})
      : inner_(inner), options_(options) {}
  cv::Mat estimate(const cv::Mat& a_bgr, const cv::Mat& b_bgr) override;
  std::string name() const override { return inner_.name() + "+homography"; }
  // The homography of the last estimate() call.
  const HomographyEstimate& last_homography() const { return last_; }

 private:
  OpticalFlow& inner_;
  HomographyOptions options_;
  HomographyEstimate last_;
};

}  // namespace cvd
