#include "pipeline/flow/flow_homography.h"

#include <spdlog/spdlog.h>

#include <cmath>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "engine/error.h"

namespace cvd {

KeypointDetector parse_keypoint_detector(const std::string& name) {
  if (name == "sift") return KeypointDetector::sift;
  if (name == "orb") return KeypointDetector::orb;
  fail(ErrorCategory::invalid_argument, "unknown keypoint detector '{}' (expected sift or orb)",
       name);
}

namespace {

cv::Mat to_gray(const cv::Mat& img) {
  CVD_CHECK(!img.empty() && img.depth() == CV_8U && (img.channels() == 3 || img.channels() == 1),
            "homography: images must be non-empty 8-bit BGR or grayscale, got type {}", img.type());
  if (img.channels() == 1) return img;
  cv::Mat gray;
  cv::cvtColor(img, gray, cv::COLOR_BGR2GRAY);
  return gray;
}

cv::Ptr<cv::Feature2D> make_detector(const HomographyOptions& o) {
  if (o.detector == KeypointDetector::orb) return cv::ORB::create(o.max_features);
  return cv::SIFT::create(o.max_features);
}

HomographyEstimate fallback(HomographyEstimate e, std::string reason) {
  e.a_to_b = cv::Matx33d::eye();
  e.identity_fallback = true;
  e.reason = std::move(reason);
  spdlog::warn("homography pre-warp: identity fallback: {}", e.reason);
  return e;
}

// Signed area of a polygon (shoelace formula).
double signed_area(const std::vector<cv::Point2d>& p) {
  double s = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    const cv::Point2d& q = p[(i + 1) % p.size()];
    s += p[i].x * q.y - q.x * p[i].y;
  }
  return 0.5 * s;
}

}  // namespace

std::string homography_degeneracy(const cv::Matx33d& g, cv::Size size, double max_area_ratio) {
  for (int i = 0; i < 9; ++i)
    if (!std::isfinite(g.val[i])) return "the homography has non-finite entries";
  const double w0 = size.width - 1.0, h0 = size.height - 1.0;
  const std::vector<cv::Point2d> corners{{0, 0}, {w0, 0}, {w0, h0}, {0, h0}};
  std::vector<cv::Point2d> mapped;
  for (const auto& c : corners) {
    const cv::Vec3d p = g * cv::Vec3d(c.x, c.y, 1.0);
    if (!(p[2] > 1e-9))
      return fmt::format(
          "it maps image corner ({}, {}) to infinity or behind "
          "the camera (w = {:.3g})",
          c.x, c.y, p[2]);
    mapped.emplace_back(p[0] / p[2], p[1] / p[2]);
  }
  // Convex and orientation-preserving: every turn has the same (positive, y down) sign.
  for (size_t i = 0; i < 4; ++i) {
    const cv::Point2d a = mapped[(i + 1) % 4] - mapped[i];
    const cv::Point2d b = mapped[(i + 2) % 4] - mapped[(i + 1) % 4];
    if (a.x * b.y - a.y * b.x <= 0)
      return "it folds or mirrors the image (mapped corners not convex in the same orientation)";
  }
  const double ratio = signed_area(mapped) / signed_area(corners);
  if (!(ratio >= 1.0 / max_area_ratio && ratio <= max_area_ratio))
    return fmt::format("it changes the image area by a factor {:.3g} (allowed 1/{} .. {})", ratio,
                       max_area_ratio, max_area_ratio);
  return "";
}

ImageKeypoints detect_keypoints(const cv::Mat& image_bgr, const HomographyOptions& options) {
  CVD_CHECK(options.max_features > 0, "homography: max_features must be > 0, got {}",
            options.max_features);
  ImageKeypoints k;
  k.image_size = image_bgr.size();
  k.detector = options.detector;
  make_detector(options)->detectAndCompute(to_gray(image_bgr), cv::noArray(), k.keypoints,
                                           k.descriptors);
  return k;
}

HomographyEstimate estimate_homography(const cv::Mat& a_bgr, const cv::Mat& b_bgr,
                                       const HomographyOptions& options) {
  CVD_CHECK(a_bgr.size() == b_bgr.size(), "homography: image sizes differ ({}x{} vs {}x{})",
            a_bgr.cols, a_bgr.rows, b_bgr.cols, b_bgr.rows);
  return estimate_homography(detect_keypoints(a_bgr, options), detect_keypoints(b_bgr, options),
                             options);
}

HomographyEstimate estimate_homography(const ImageKeypoints& a, const ImageKeypoints& b,
                                       const HomographyOptions& options) {
  CVD_CHECK(a.image_size == b.image_size, "homography: image sizes differ ({}x{} vs {}x{})",
            a.image_size.width, a.image_size.height, b.image_size.width, b.image_size.height);
  CVD_CHECK(a.detector == b.detector && a.detector == options.detector,
            "homography: keypoints come from different detectors");
  CVD_CHECK(options.lowe_ratio > 0 && options.lowe_ratio <= 1,
            "homography: Lowe ratio must be in (0, 1], got {}", options.lowe_ratio);
  CVD_CHECK(options.min_inliers >= 4, "homography: min_inliers must be >= 4, got {}",
            options.min_inliers);
  HomographyEstimate e;
  const auto& ka = a.keypoints;
  const auto& kb = b.keypoints;
  const cv::Mat& da = a.descriptors;
  const cv::Mat& db = b.descriptors;
  e.keypoints_a = static_cast<int>(ka.size());
  e.keypoints_b = static_cast<int>(kb.size());
  if (ka.size() < 4 || kb.size() < 4 || da.empty() || db.empty())
    return fallback(e, fmt::format("too few keypoints ({} in a, {} in b)", ka.size(), kb.size()));

  const int norm = options.detector == KeypointDetector::orb ? cv::NORM_HAMMING : cv::NORM_L2;
  cv::BFMatcher matcher(norm);
  std::vector<std::vector<cv::DMatch>> knn;
  matcher.knnMatch(da, db, knn, 2);
  std::vector<cv::Point2f> pa, pb;
  for (const auto& m : knn) {
    if (m.size() < 2 || m[0].distance >= options.lowe_ratio * m[1].distance) continue;
    pa.push_back(ka[m[0].queryIdx].pt);
    pb.push_back(kb[m[0].trainIdx].pt);
  }
  e.matches = static_cast<int>(pa.size());
  if (e.matches < options.min_inliers)
    return fallback(e, fmt::format("only {} matches pass the ratio test {} (need {})", e.matches,
                                   options.lowe_ratio, options.min_inliers));

  std::vector<unsigned char> inlier_mask;
  cv::Mat g =
      cv::findHomography(pa, pb, cv::RANSAC, options.ransac_threshold_px, inlier_mask, 2000, 0.995);
  if (g.empty()) return fallback(e, "RANSAC found no homography");
  e.inliers = cv::countNonZero(inlier_mask);
  if (e.inliers < options.min_inliers)
    return fallback(e, fmt::format("only {} RANSAC inliers of {} matches (need {})", e.inliers,
                                   e.matches, options.min_inliers));
  cv::Matx33d gm(g);
  if (!(std::abs(gm(2, 2)) > 1e-12)) return fallback(e, "the homography has G(2,2) = 0");
  gm *= 1.0 / gm(2, 2);
  const std::string degenerate = homography_degeneracy(gm, a.image_size, options.max_area_ratio);
  if (!degenerate.empty()) return fallback(e, "degenerate homography: " + degenerate);
  e.a_to_b = gm;
  e.identity_fallback = false;
  spdlog::debug("homography pre-warp: {} keypoints / {} matches / {} inliers", e.keypoints_a,
                e.matches, e.inliers);
  return e;
}

cv::Mat compose_homography_flow(const cv::Mat& residual, const cv::Matx33d& g) {
  CVD_CHECK(residual.type() == CV_32FC2, "compose_homography_flow: residual must be CV_32FC2");
  cv::Mat out(residual.size(), CV_32FC2);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  cv::parallel_for_(cv::Range(0, residual.rows), [&](const cv::Range& rows) {
    for (int y = rows.start; y < rows.end; ++y) {
      const cv::Vec2f* r = residual.ptr<cv::Vec2f>(y);
      cv::Vec2f* f = out.ptr<cv::Vec2f>(y);
      for (int x = 0; x < residual.cols; ++x) {
        const double px = x + double(r[x][0]), py = y + double(r[x][1]);
        const double w = g(2, 0) * px + g(2, 1) * py + g(2, 2);
        if (!(w > 1e-12)) {
          f[x] = cv::Vec2f(nan, nan);
          continue;
        }
        const double qx = (g(0, 0) * px + g(0, 1) * py + g(0, 2)) / w;
        const double qy = (g(1, 0) * px + g(1, 1) * py + g(1, 2)) / w;
        f[x] = cv::Vec2f(float(qx - x), float(qy - y));
      }
    }
  });
  return out;
}

cv::Mat homography_flow(const cv::Matx33d& a_to_b, cv::Size size) {
  return compose_homography_flow(cv::Mat::zeros(size, CV_32FC2), a_to_b);
}

cv::Mat flow_through_homography(OpticalFlow& estimator, const cv::Mat& a_bgr, const cv::Mat& b_bgr,
                                const cv::Matx33d& a_to_b) {
  CVD_CHECK(a_bgr.size() == b_bgr.size(), "homography pre-warp: image sizes differ");
  if (a_to_b == cv::Matx33d::eye()) return estimator.estimate(a_bgr, b_bgr);
  cv::Mat b_aligned;
  cv::warpPerspective(b_bgr, b_aligned, cv::Mat(a_to_b), a_bgr.size(),
                      cv::INTER_LINEAR | cv::WARP_INVERSE_MAP, cv::BORDER_REPLICATE);
  return compose_homography_flow(estimator.estimate(a_bgr, b_aligned), a_to_b);
}

cv::Mat HomographyPrewarpedFlow::estimate(const cv::Mat& a_bgr, const cv::Mat& b_bgr) {
  last_ = estimate_homography(a_bgr, b_bgr, options_);
  return flow_through_homography(inner_, a_bgr, b_bgr, last_.a_to_b);
}

}  // namespace cvd
