#include "pipeline/geometry/disparity_affine.h"

#include <algorithm>
#include <cmath>

#include "engine/error.h"
#include "pipeline/geometry/median.h"

namespace cvd {

namespace {

// Weighted least squares of y ~ a x + b; false when degenerate (no spread in x).
bool weighted_line(const std::vector<double>& x, const std::vector<double>& y,
                   const std::vector<double>& w, double& a, double& b) {
  double sw = 0, sx = 0, sy = 0;
  for (size_t i = 0; i < x.size(); ++i) {
    sw += w[i];
    sx += w[i] * x[i];
    sy += w[i] * y[i];
  }
  if (sw <= 0) return false;
  const double mx = sx / sw, my = sy / sw;
  double sxx = 0, sxy = 0;
  for (size_t i = 0; i < x.size(); ++i) {
    sxx += w[i] * (x[i] - mx) * (x[i] - mx);
    sxy += w[i] * (x[i] - mx) * (y[i] - my);
  }
  if (!(sxx > 1e-18 * sw * (mx * mx + 1e-30))) return false;
  a = sxy / sxx;
  b = my - a * mx;
  return std::isfinite(a) && std::isfinite(b);
}

}  // namespace

DisparityAffineFit fit_disparity_affine(const std::vector<double>& raw,
                                        const std::vector<double>& depth) {
  CVD_CHECK(raw.size() == depth.size(), "fit_disparity_affine: {} raw values for {} depths",
            raw.size(), depth.size());
  std::vector<double> x, y;
  for (size_t i = 0; i < raw.size(); ++i)
    if (raw[i] > 0 && depth[i] > 0 && std::isfinite(raw[i]) && std::isfinite(depth[i])) {
      x.push_back(raw[i]);
      y.push_back(1.0 / depth[i]);
    }
  DisparityAffineFit fit;
  fit.samples = static_cast<int>(x.size());
  if (x.empty())
    fail(ErrorCategory::numerical,
         "disparity calibration: no sparse point has a positive depth and network output");
  const double median_disparity = upper_median(y);
  fit.floor = 1e-3 * median_disparity;
  std::vector<double> w(x.size(), 1.0), r(x.size());
  double a = 0, b = 0;
  bool ok = weighted_line(x, y, w, a, b);
  for (int it = 0; ok && it < 50; ++it) {
    for (size_t i = 0; i < x.size(); ++i) r[i] = std::abs(a * x[i] + b - y[i]);
    const double threshold = std::max(1.5 * 1.4826 * upper_median(r), 1e-9 * median_disparity);
    for (size_t i = 0; i < x.size(); ++i) w[i] = r[i] <= threshold ? 1.0 : threshold / r[i];
    double a2 = a, b2 = b;
    ok = weighted_line(x, y, w, a2, b2);
    const bool settled = std::abs(a2 - a) <= 1e-10 * std::abs(a) &&
                         std::abs(b2 - b) <= 1e-10 * (std::abs(b) + median_disparity);
    a = a2;
    b = b2;
    if (settled) break;
  }
  if (!ok || !(a > 0)) {
    std::vector<double> ratio(x.size());
    for (size_t i = 0; i < x.size(); ++i) ratio[i] = y[i] / x[i];
    a = upper_median(ratio);
    b = 0;
    fit.scale_only = true;
  }
  fit.scale = a;
  fit.shift = b;
  for (size_t i = 0; i < x.size(); ++i) r[i] = std::abs(a * x[i] + b - y[i]);
  fit.residual_mad = upper_median(r);
  const double threshold = std::max(1.5 * 1.4826 * fit.residual_mad, 1e-9 * median_disparity);
  for (double v : r) fit.inliers += v <= threshold;
  return fit;
}

}  // namespace cvd
