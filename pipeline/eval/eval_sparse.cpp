// Sparse SfM depth vs GT depth: the metrics of a run's sparse points. See eval_sparse.h.
#include "pipeline/eval/eval_sparse.h"

#include <algorithm>
#include <cmath>

#include "engine/error.h"
#include "pipeline/geometry/median.h"

namespace cvd {

SparseDepthEval evaluate_sparse_depth(const std::map<std::string, SparseDepthFrame>& sparse,
                                      const std::vector<std::string>& names,
                                      const std::vector<cv::Mat>& gt_depths, double min_depth,
                                      double max_depth) {
  CVD_CHECK(names.size() == gt_depths.size(), "evaluate_sparse_depth: {} names, {} GT maps",
            names.size(), gt_depths.size());
  struct FramePairs {
    std::vector<double> z, d;
    double pixels = 0;
  };
  std::vector<FramePairs> per;
  for (size_t i = 0; i < names.size(); ++i) {
    auto it = sparse.find(names[i]);
    if (it == sparse.end() || it->second.points.empty()) continue;
    const SparseDepthFrame& f = it->second;
    const cv::Mat& g = gt_depths[i];
    CVD_CHECK(g.type() == CV_32FC1, "evaluate_sparse_depth: GT of '{}' must be CV_32FC1", names[i]);
    const double sx = double(g.cols) / f.width, sy = double(g.rows) / f.height;
    FramePairs fp;
    fp.pixels = double(f.width) * f.height;
    for (const auto& p : f.points) {
      const int x = static_cast<int>(std::lround((p.u + 0.5) * sx - 0.5));
      const int y = static_cast<int>(std::lround((p.v + 0.5) * sy - 0.5));
      if (x < 0 || y < 0 || x >= g.cols || y >= g.rows) continue;
      const double d = g.at<float>(y, x);
      if (!std::isfinite(d) || d <= min_depth || (max_depth > 0 && d >= max_depth)) continue;
      fp.z.push_back(p.z);
      fp.d.push_back(d);
    }
    if (!fp.z.empty()) per.push_back(std::move(fp));
  }
  SparseDepthEval r;
  r.frames = static_cast<int>(per.size());
  if (per.empty()) return r;
  std::vector<double> all_ratios;
  for (const auto& fp : per)
    for (size_t k = 0; k < fp.z.size(); ++k) all_ratios.push_back(fp.d[k] / fp.z[k]);
  const double video_scale = upper_median(all_ratios);
  int64_t within = 0;
  for (const auto& fp : per) {
    std::vector<double> ratios;
    for (size_t k = 0; k < fp.z.size(); ++k) ratios.push_back(fp.d[k] / fp.z[k]);
    const double s = upper_median(ratios);
    double sum = 0, sum_video = 0;
    for (size_t k = 0; k < fp.z.size(); ++k) {
      const double e = s * fp.z[k];
      sum += std::abs(e - fp.d[k]) / fp.d[k];
      sum_video += std::abs(video_scale * fp.z[k] - fp.d[k]) / fp.d[k];
      within += std::max(e / fp.d[k], fp.d[k] / e) < 1.25;
    }
    r.points += static_cast<int64_t>(fp.z.size());
    r.abs_rel += sum / fp.z.size();
    r.abs_rel_video += sum_video / fp.z.size();
    r.density += fp.z.size() / fp.pixels;
  }
  r.abs_rel /= per.size();
  r.abs_rel_video /= per.size();
  r.density /= per.size();
  r.delta1 = double(within) / double(r.points);
  return r;
}

}  // namespace cvd
