#include "pipeline/eval/eval_texture_split.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>

#include "engine/error.h"

namespace cvd {

cv::Mat low_texture_mask(const cv::Mat& grey, cv::Size size, const TextureSplitOptions& opt) {
  CVD_CHECK(!grey.empty() && grey.type() == CV_8UC1, "low_texture_mask: needs a CV_8U grey image");
  CVD_CHECK(opt.long_side >= 8, "low_texture_mask: long side {} is too small", opt.long_side);
  const double s = double(opt.long_side) / std::max(grey.cols, grey.rows);
  const cv::Size small(std::max(1, int(std::lround(grey.cols * s))),
                       std::max(1, int(std::lround(grey.rows * s))));
  cv::Mat g = grey, gx, gy, magnitude;
  if (small != grey.size()) cv::resize(grey, g, small, 0, 0, cv::INTER_AREA);
  cv::Sobel(g, gx, CV_32F, 1, 0);
  cv::Sobel(g, gy, CV_32F, 0, 1);
  cv::magnitude(gx, gy, magnitude);
  cv::Mat low = magnitude < opt.threshold;
  if (low.size() != size) cv::resize(low, low, size, 0, 0, cv::INTER_NEAREST);
  return low;
}

TextureSplit depth_errors_by_texture(const std::vector<cv::Mat>& preds,
                                     const std::vector<cv::Mat>& gts,
                                     const std::vector<cv::Mat>& greys,
                                     const DepthEvalResult& median_frame,
                                     const DepthEvalOptions& depth_opt,
                                     const TextureSplitOptions& opt) {
  CVD_CHECK(preds.size() == gts.size() && preds.size() == greys.size(),
            "depth_errors_by_texture: {} predictions, {} GT maps, {} frames", preds.size(),
            gts.size(), greys.size());
  CVD_CHECK(median_frame.alignment == DepthAlignment::median_frame &&
                median_frame.space == DepthSpace::depth && median_frame.fits.size() == preds.size(),
            "depth_errors_by_texture: needs the median_frame depth result of the same frames");
  // Per-frame errors of each region (depth_errors: means over its pixels), pooled by pixel count.
  struct Sums {
    double abs_rel = 0, delta1 = 0;
    long long n = 0;
    void add(const DepthErrors& e) {
      abs_rel += e.abs_rel * double(e.count);
      delta1 += e.delta1 * double(e.count);
      n += e.count;
    }
  } low, rest;
  for (size_t i = 0; i < preds.size(); ++i) {
    const cv::Mat valid = valid_depth_mask(preds[i], gts[i], depth_opt);
    const cv::Mat p = apply_fit(preds[i], median_frame.fits[i], DepthSpace::depth, depth_opt);
    const cv::Mat flat = low_texture_mask(greys[i], gts[i].size(), opt);
    low.add(depth_errors(p, gts[i], valid & flat));
    rest.add(depth_errors(p, gts[i], valid & ~flat));
  }
  const long long total = low.n + rest.n;
  auto region = [&](const Sums& s) {
    RegionDepthErrors r;
    r.pixels = s.n;
    r.share = total > 0 ? double(s.n) / double(total) : 0.0;
    if (s.n > 0) r.abs_rel = s.abs_rel / double(s.n), r.delta1 = s.delta1 / double(s.n);
    return r;
  };
  return {region(low), region(rest)};
}

}  // namespace cvd
