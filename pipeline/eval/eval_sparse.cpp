// Sparse SfM depth vs GT depth: reader/writer of sparse_depth.csv and its metrics. See
// eval_sparse.h.
#include "pipeline/eval/eval_sparse.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include "engine/error.h"
#include "pipeline/geometry/median.h"
#include "pipeline/io/atomic_file.h"

namespace fs = std::filesystem;

namespace cvd {

namespace {

constexpr const char* kHeader = "frame,width,height,u,v,z";

}  // namespace

std::map<std::string, SparseDepthFrame> read_sparse_depth_csv(const fs::path& path) {
  std::ifstream in(path);
  if (!in) fail(ErrorCategory::io, "{}: cannot open", path.string());
  std::map<std::string, SparseDepthFrame> out;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty()) continue;
    if (line_no == 1) {
      if (line != kHeader)
        fail(ErrorCategory::format, "{}: line 1 must be the header '{}', got '{}'", path.string(),
             kHeader, line.substr(0, 80));
      continue;
    }
    auto comma = line.find(',');
    if (comma == std::string::npos || comma == 0)
      fail(ErrorCategory::format, "{}:{}: expected 'frame,width,height,u,v,z'", path.string(),
           line_no);
    std::string name = line.substr(0, comma);
    std::string rest = line.substr(comma + 1);
    std::replace(rest.begin(), rest.end(), ',', ' ');
    std::istringstream ss(rest);
    int w = 0, h = 0;
    SparseDepthPoint p;
    std::string extra;
    if (!(ss >> w >> h >> p.u >> p.v >> p.z) || (ss >> extra))
      fail(ErrorCategory::format, "{}:{}: expected 'frame,width,height,u,v,z'", path.string(),
           line_no);
    if (w <= 0 || h <= 0 || !std::isfinite(p.u) || !std::isfinite(p.v) || !std::isfinite(p.z) ||
        p.z <= 0)
      fail(ErrorCategory::format,
           "{}:{}: size must be positive and u, v, z finite with z > 0 (got {}x{}, z {})",
           path.string(), line_no, w, h, p.z);
    SparseDepthFrame& f = out[name];
    if (f.points.empty()) {
      f.width = w;
      f.height = h;
    } else if (f.width != w || f.height != h) {
      fail(ErrorCategory::format, "{}:{}: frame '{}' changes size from {}x{} to {}x{}",
           path.string(), line_no, name, f.width, f.height, w, h);
    }
    f.points.push_back(p);
  }
  if (line_no == 0) fail(ErrorCategory::format, "{}: empty file (no header)", path.string());
  return out;
}

void write_sparse_depth_csv(const fs::path& path,
                            const std::map<std::string, SparseDepthFrame>& frames) {
  std::string s = std::string(kHeader) + "\n";
  for (const auto& [name, f] : frames) {
    CVD_CHECK(name.find(',') == std::string::npos, "sparse_depth.csv: frame name '{}' has a comma",
              name);
    for (const auto& p : f.points)
      s += fmt::format("{},{},{},{:.3f},{:.3f},{:.9g}\n", name, f.width, f.height, p.u, p.v, p.z);
  }
  write_text_file(path, s);
}

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
