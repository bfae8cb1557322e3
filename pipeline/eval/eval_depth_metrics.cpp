// Depth accuracy metrics and alignments; formulas in eval_depth_metrics.h.
#include "pipeline/eval/eval_depth_metrics.h"

#include <algorithm>
#include <cmath>

#include "engine/error.h"
#include "pipeline/geometry/median.h"

namespace cvd {

const char* depth_alignment_name(DepthAlignment a) {
  switch (a) {
    case DepthAlignment::none:
      return "none";
    case DepthAlignment::median_frame:
      return "median_frame";
    case DepthAlignment::median_video:
      return "median_video";
    case DepthAlignment::lstsq_frame:
      return "lstsq_frame";
  }
  return "?";
}

const char* depth_space_name(DepthSpace s) {
  return s == DepthSpace::depth ? "depth" : "disparity";
}

static void check_pair(const cv::Mat& pred, const cv::Mat& gt, const char* what) {
  CVD_CHECK(pred.type() == CV_32F && gt.type() == CV_32F,
            "{}: prediction and ground truth must be single-channel float maps", what);
  CVD_CHECK(pred.size() == gt.size(), "{}: prediction is {}x{} but ground truth is {}x{}", what,
            pred.cols, pred.rows, gt.cols, gt.rows);
}

cv::Mat valid_depth_mask(const cv::Mat& pred, const cv::Mat& gt, const DepthEvalOptions& opt) {
  check_pair(pred, gt, "valid_depth_mask");
  cv::Mat mask(gt.size(), CV_8U, cv::Scalar(0));
  for (int y = 0; y < gt.rows; ++y) {
    const float* p = pred.ptr<float>(y);
    const float* g = gt.ptr<float>(y);
    uint8_t* m = mask.ptr<uint8_t>(y);
    for (int x = 0; x < gt.cols; ++x) {
      bool ok = std::isfinite(g[x]) && g[x] > opt.min_depth &&
                (opt.max_depth <= 0 || g[x] < opt.max_depth) && std::isfinite(p[x]) && p[x] > 0;
      m[x] = ok ? 255 : 0;
    }
  }
  return mask;
}

DepthErrors depth_errors(const cv::Mat& pred, const cv::Mat& gt, const cv::Mat& mask) {
  check_pair(pred, gt, "depth_errors");
  double abs_rel = 0, sq_rel = 0, sq = 0, sq_log = 0;
  long long n = 0, d1 = 0, d2 = 0, d3 = 0;
  for (int y = 0; y < gt.rows; ++y) {
    const float* p = pred.ptr<float>(y);
    const float* g = gt.ptr<float>(y);
    const uint8_t* m = mask.ptr<uint8_t>(y);
    for (int x = 0; x < gt.cols; ++x) {
      if (!m[x]) continue;
      double pv = p[x], gv = g[x], e = pv - gv;
      abs_rel += std::abs(e) / gv;
      sq_rel += e * e / gv;
      sq += e * e;
      double le = std::log(pv) - std::log(gv);
      sq_log += le * le;
      double ratio = std::max(pv / gv, gv / pv);
      d1 += ratio < 1.25;
      d2 += ratio < 1.25 * 1.25;
      d3 += ratio < 1.25 * 1.25 * 1.25;
      ++n;
    }
  }
  DepthErrors r;
  r.count = n;
  if (n == 0) return r;
  r.abs_rel = abs_rel / n;
  r.sq_rel = sq_rel / n;
  r.rmse = std::sqrt(sq / n);
  r.rmse_log = std::sqrt(sq_log / n);
  r.delta1 = double(d1) / n;
  r.delta2 = double(d2) / n;
  r.delta3 = double(d3) / n;
  return r;
}

static void append_ratios(const cv::Mat& pred, const cv::Mat& gt, const cv::Mat& mask,
                          std::vector<double>& out) {
  for (int y = 0; y < gt.rows; ++y) {
    const float* p = pred.ptr<float>(y);
    const float* g = gt.ptr<float>(y);
    const uint8_t* m = mask.ptr<uint8_t>(y);
    for (int x = 0; x < gt.cols; ++x)
      if (m[x]) out.push_back(double(g[x]) / p[x]);
  }
}

DepthAlignmentFit fit_median_scale(const cv::Mat& pred, const cv::Mat& gt, const cv::Mat& mask) {
  check_pair(pred, gt, "fit_median_scale");
  std::vector<double> ratios;
  append_ratios(pred, gt, mask, ratios);
  return {median(std::move(ratios), 1.0), 0.0};
}

DepthAlignmentFit fit_lstsq_scale_shift(const cv::Mat& pred, const cv::Mat& gt,
                                        const cv::Mat& mask) {
  check_pair(pred, gt, "fit_lstsq_scale_shift");
  // Normal equations of min sum (s p + b - g)^2, accumulated in double.
  double spp = 0, sp = 0, sg = 0, spg = 0;
  long long n = 0;
  for (int y = 0; y < gt.rows; ++y) {
    const float* p = pred.ptr<float>(y);
    const float* g = gt.ptr<float>(y);
    const uint8_t* m = mask.ptr<uint8_t>(y);
    for (int x = 0; x < gt.cols; ++x) {
      if (!m[x]) continue;
      spp += double(p[x]) * p[x];
      sp += p[x];
      sg += g[x];
      spg += double(p[x]) * g[x];
      ++n;
    }
  }
  if (n < 2) return {};
  double det = n * spp - sp * sp;
  if (std::abs(det) <= 1e-12 * std::max(1.0, n * spp)) {
    // Constant prediction: only a shift can be fitted.
    return {0.0, sg / n};
  }
  double s = (n * spg - sp * sg) / det;
  double b = (sg - s * sp) / n;
  return {s, b};
}

// Converts a depth map to the evaluation space (disparity = 1/d; non-positive stays invalid).
static cv::Mat to_space(const cv::Mat& depth, DepthSpace space) {
  if (space == DepthSpace::depth) return depth;
  cv::Mat out(depth.size(), CV_32F);
  for (int y = 0; y < depth.rows; ++y) {
    const float* d = depth.ptr<float>(y);
    float* o = out.ptr<float>(y);
    for (int x = 0; x < depth.cols; ++x)
      o[x] = (std::isfinite(d[x]) && d[x] > 0) ? 1.0f / d[x] : 0.0f;
  }
  return out;
}

cv::Mat apply_fit(const cv::Mat& p, const DepthAlignmentFit& f, DepthSpace space,
                  const DepthEvalOptions& opt) {
  double lo, hi;
  if (space == DepthSpace::depth) {
    lo = opt.min_depth > 0 ? opt.min_depth : 1e-6;
    hi = opt.max_depth > 0 ? opt.max_depth : HUGE_VAL;
  } else {
    lo = opt.max_depth > 0 ? 1.0 / opt.max_depth : 1e-9;
    hi = opt.min_depth > 0 ? 1.0 / opt.min_depth : HUGE_VAL;
  }
  cv::Mat out(p.size(), CV_32F);
  for (int y = 0; y < p.rows; ++y) {
    const float* a = p.ptr<float>(y);
    float* o = out.ptr<float>(y);
    for (int x = 0; x < p.cols; ++x) o[x] = float(std::clamp(f.scale * a[x] + f.shift, lo, hi));
  }
  return out;
}

DepthEvalResult evaluate_video_depth(const std::vector<cv::Mat>& preds,
                                     const std::vector<cv::Mat>& gts, DepthAlignment alignment,
                                     DepthSpace space, const DepthEvalOptions& opt,
                                     int curve_points) {
  CVD_CHECK(preds.size() == gts.size(), "evaluate_video_depth: {} predictions for {} GT frames",
            preds.size(), gts.size());
  DepthEvalResult r;
  r.alignment = alignment;
  r.space = space;
  const size_t n = preds.size();
  std::vector<cv::Mat> masks(n), ps(n), gs(n);
  for (size_t i = 0; i < n; ++i) {
    masks[i] = valid_depth_mask(preds[i], gts[i], opt);
    ps[i] = to_space(preds[i], space);
    gs[i] = to_space(gts[i], space);
  }
  DepthAlignmentFit video_fit;
  if (alignment == DepthAlignment::median_video) {
    std::vector<double> ratios;
    for (size_t i = 0; i < n; ++i) append_ratios(ps[i], gs[i], masks[i], ratios);
    video_fit = {median(std::move(ratios), 1.0), 0.0};
  }
  std::vector<float> pixel_errors;
  double sums[7] = {0, 0, 0, 0, 0, 0, 0};
  long long used = 0;
  for (size_t i = 0; i < n; ++i) {
    DepthAlignmentFit fit;
    switch (alignment) {
      case DepthAlignment::none:
        break;
      case DepthAlignment::median_frame:
        fit = fit_median_scale(ps[i], gs[i], masks[i]);
        break;
      case DepthAlignment::median_video:
        fit = video_fit;
        break;
      case DepthAlignment::lstsq_frame:
        fit = fit_lstsq_scale_shift(ps[i], gs[i], masks[i]);
        break;
    }
    r.fits.push_back(fit);
    cv::Mat aligned = apply_fit(ps[i], fit, space, opt);
    DepthErrors e = depth_errors(aligned, gs[i], masks[i]);
    r.per_frame.push_back(e);
    if (e.count == 0) {
      ++r.skipped_frames;
      continue;
    }
    ++used;
    double v[7] = {e.abs_rel, e.sq_rel, e.rmse, e.rmse_log, e.delta1, e.delta2, e.delta3};
    for (int k = 0; k < 7; ++k) sums[k] += v[k];
    for (int y = 0; y < aligned.rows; ++y) {
      const float* a = aligned.ptr<float>(y);
      const float* g = gs[i].ptr<float>(y);
      const uint8_t* m = masks[i].ptr<uint8_t>(y);
      for (int x = 0; x < aligned.cols; ++x)
        if (m[x]) pixel_errors.push_back(std::abs(a[x] - g[x]) / g[x]);
    }
  }
  r.mean.count = used;
  if (used > 0) {
    r.mean.abs_rel = sums[0] / used;
    r.mean.sq_rel = sums[1] / used;
    r.mean.rmse = sums[2] / used;
    r.mean.rmse_log = sums[3] / used;
    r.mean.delta1 = sums[4] / used;
    r.mean.delta2 = sums[5] / used;
    r.mean.delta3 = sums[6] / used;
  }
  std::sort(pixel_errors.begin(), pixel_errors.end());
  if (!pixel_errors.empty() && curve_points > 1) {
    int k = int(std::min<size_t>(curve_points, pixel_errors.size()));
    for (int j = 0; j < k; ++j) {
      size_t idx = k == 1 ? 0 : size_t(double(j) / (k - 1) * (pixel_errors.size() - 1));
      r.sorted_abs_rel.push_back(pixel_errors[idx]);
    }
  }
  return r;
}

}  // namespace cvd
