// The self-contained HTML report of `cvd eval`: metric tables, inline SVG plots (sorted per-pixel
// error curves as in the paper's quantitative figure, per-frame error over time, a top view of
// the estimated vs GT trajectory, per-pair flow-reprojection error) and depth thumbnails as
// inline base64 PNGs. No external resources: the file renders offline.
#pragma once
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include <filesystem>
#include <string>
#include <vector>

namespace cvd {

struct ReportThumbnail {
  std::string caption;
  std::vector<unsigned char> png;  // encoded PNG bytes
};

// One named polyline of a plot.
struct PlotSeries {
  std::string name;
  std::vector<double> x, y;
};

// An SVG line plot (axes, ticks, legend) of the series; `equal_aspect` keeps one unit the same
// length on both axes (for trajectories). Non-finite points are skipped.
std::string svg_line_plot(const std::string& title, const std::string& x_label,
                          const std::string& y_label, const std::vector<PlotSeries>& series,
                          bool equal_aspect = false);

std::string base64_encode(const std::vector<unsigned char>& bytes);

// The colour scale of the thumbnails as a PNG, near (left) to far (right).
std::vector<unsigned char> depth_colour_bar_png(int width, int height);

// Colour-mapped (turbo) PNG of a CV_32F depth map; near = warm. Invalid pixels (<= 0 or
// non-finite) are black. [lo, hi] is the depth range mapped (use one range per video).
std::vector<unsigned char> depth_thumbnail_png(const cv::Mat& depth, double lo, double hi,
                                               int max_width = 256);

// The report's HTML for `metrics` (the metrics.json object of evaluate_run).
std::string render_eval_report(const nlohmann::json& metrics,
                               const std::vector<ReportThumbnail>& thumbnails);

// Writes render_eval_report(...) atomically to `path`.
void write_eval_report(const std::filesystem::path& path, const nlohmann::json& metrics,
                       const std::vector<ReportThumbnail>& thumbnails);

}  // namespace cvd
