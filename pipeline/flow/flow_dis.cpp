#include "pipeline/flow/flow_dis.h"

#include <algorithm>
#include <opencv2/imgproc.hpp>

#include "engine/error.h"

namespace cvd {

DisPreset parse_dis_preset(const std::string& name) {
  if (name == "ultrafast") return DisPreset::ultrafast;
  if (name == "fast") return DisPreset::fast;
  if (name == "medium") return DisPreset::medium;
  fail(ErrorCategory::invalid_argument,
       "unknown DIS preset '{}' (expected ultrafast, fast or medium)", name);
}

const char* dis_preset_name(DisPreset preset) {
  switch (preset) {
    case DisPreset::ultrafast:
      return "ultrafast";
    case DisPreset::fast:
      return "fast";
    case DisPreset::medium:
      return "medium";
  }
  return "?";
}

namespace {

int opencv_preset(DisPreset p) {
  switch (p) {
    case DisPreset::ultrafast:
      return cv::DISOpticalFlow::PRESET_ULTRAFAST;
    case DisPreset::fast:
      return cv::DISOpticalFlow::PRESET_FAST;
    case DisPreset::medium:
      return cv::DISOpticalFlow::PRESET_MEDIUM;
  }
  return cv::DISOpticalFlow::PRESET_MEDIUM;
}

cv::Mat to_gray(const cv::Mat& img, const char* which) {
  CVD_CHECK(!img.empty(), "DIS flow: image {} is empty", which);
  CVD_CHECK(img.depth() == CV_8U && (img.channels() == 3 || img.channels() == 1),
            "DIS flow: image {} must be 8-bit BGR or grayscale, got type {}", which, img.type());
  if (img.channels() == 1) return img;
  cv::Mat gray;
  cv::cvtColor(img, gray, cv::COLOR_BGR2GRAY);
  return gray;
}

}  // namespace

DisFlowEstimator::DisFlowEstimator(const DisFlowOptions& options)
    : options_(options), dis_(cv::DISOpticalFlow::create(opencv_preset(options.preset))) {
  if (options.variational_refinement_iterations) {
    CVD_CHECK(*options.variational_refinement_iterations >= 0,
              "DIS: variational refinement iterations must be >= 0, got {}",
              *options.variational_refinement_iterations);
    dis_->setVariationalRefinementIterations(*options.variational_refinement_iterations);
  }
  if (options.variational_refinement_alpha)
    dis_->setVariationalRefinementAlpha(*options.variational_refinement_alpha);
  if (options.variational_refinement_delta)
    dis_->setVariationalRefinementDelta(*options.variational_refinement_delta);
  if (options.variational_refinement_gamma)
    dis_->setVariationalRefinementGamma(*options.variational_refinement_gamma);
  if (options.finest_scale) {
    CVD_CHECK(*options.finest_scale >= 0, "DIS: finest scale must be >= 0, got {}",
              *options.finest_scale);
    dis_->setFinestScale(*options.finest_scale);
  }
}

cv::Mat DisFlowEstimator::estimate(const cv::Mat& a_bgr, const cv::Mat& b_bgr) {
  CVD_CHECK(a_bgr.size() == b_bgr.size(), "DIS flow: image sizes differ ({}x{} vs {}x{})",
            a_bgr.cols, a_bgr.rows, b_bgr.cols, b_bgr.rows);
  const cv::Mat a = to_gray(a_bgr, "a"), b = to_gray(b_bgr, "b");
  CVD_CHECK(std::max(a.cols, a.rows) >= 12,
            "DIS flow: images of {}x{} are too small (width or height must be >= 12)", a.cols,
            a.rows);
  cv::Mat flow;
  try {
    dis_->calc(a, b, flow);
  } catch (const cv::Exception& e) {
    fail(ErrorCategory::invalid_argument, "DIS flow failed on {}x{} images: {}", a.cols, a.rows,
         e.what());
  }
  CVD_ASSERT(flow.type() == CV_32FC2 && flow.size() == a.size());
  return flow;
}

std::string DisFlowEstimator::name() const {
  return std::string("dis-") + dis_preset_name(options_.preset);
}

}  // namespace cvd
