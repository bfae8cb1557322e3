// HTML report of an evaluation: tables, inline SVG plots and base64 thumbnails.
#include "pipeline/eval/eval_report.h"

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>

#include "engine/error.h"
#include "pipeline/io/atomic_file.h"

namespace cvd {

std::string base64_encode(const std::vector<unsigned char>& in) {
  static const char* tbl = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((in.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 2 < in.size(); i += 3) {
    unsigned v = (in[i] << 16) | (in[i + 1] << 8) | in[i + 2];
    for (int s = 18; s >= 0; s -= 6) out += tbl[(v >> s) & 63];
  }
  if (size_t rest = in.size() - i; rest > 0) {
    unsigned v = in[i] << 16 | (rest == 2 ? in[i + 1] << 8 : 0);
    out += tbl[(v >> 18) & 63];
    out += tbl[(v >> 12) & 63];
    out += rest == 2 ? tbl[(v >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

static std::string html_escape(const std::string& s) {
  std::string o;
  for (char c : s) {
    switch (c) {
      case '&':
        o += "&amp;";
        break;
      case '<':
        o += "&lt;";
        break;
      case '>':
        o += "&gt;";
        break;
      case '"':
        o += "&quot;";
        break;
      default:
        o += c;
    }
  }
  return o;
}

static const char* kColours[] = {"#1f77b4", "#d62728", "#2ca02c", "#ff7f0e",
                                 "#9467bd", "#8c564b", "#e377c2", "#17becf"};

std::string svg_line_plot(const std::string& title, const std::string& x_label,
                          const std::string& y_label, const std::vector<PlotSeries>& series,
                          bool equal_aspect) {
  const double W = 560, H = 340, L = 64, R = 16, T = 28, B = 44;
  double x0 = HUGE_VAL, x1 = -HUGE_VAL, y0 = HUGE_VAL, y1 = -HUGE_VAL;
  for (auto& s : series)
    for (size_t i = 0; i < std::min(s.x.size(), s.y.size()); ++i)
      if (std::isfinite(s.x[i]) && std::isfinite(s.y[i])) {
        x0 = std::min(x0, s.x[i]), x1 = std::max(x1, s.x[i]);
        y0 = std::min(y0, s.y[i]), y1 = std::max(y1, s.y[i]);
      }
  if (!(x0 <= x1)) x0 = 0, x1 = 1, y0 = 0, y1 = 1;
  if (x1 - x0 < 1e-12) x0 -= 0.5, x1 += 0.5;
  if (y1 - y0 < 1e-12) y0 -= 0.5, y1 += 0.5;
  double pw = W - L - R, ph = H - T - B;
  if (equal_aspect) {  // grow the tighter range so both axes share one scale
    double k = std::max((x1 - x0) / pw, (y1 - y0) / ph);
    double cx = 0.5 * (x0 + x1), cy = 0.5 * (y0 + y1);
    x0 = cx - 0.5 * k * pw, x1 = cx + 0.5 * k * pw;
    y0 = cy - 0.5 * k * ph, y1 = cy + 0.5 * k * ph;
  }
  auto sx = [&](double x) { return L + (x - x0) / (x1 - x0) * pw; };
  auto sy = [&](double y) { return T + ph - (y - y0) / (y1 - y0) * ph; };
  std::string o = fmt::format(
      "<svg class=\"plot\" xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"{}\" "
      "viewBox=\"0 0 {} {}\" font-family=\"sans-serif\" font-size=\"11\">\n"
      "<title>{}</title><rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n"
      "<text x=\"{}\" y=\"16\" text-anchor=\"middle\" font-size=\"13\">{}</text>\n",
      W, H, W, H, html_escape(title), W / 2, html_escape(title));
  o += fmt::format(
      "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"#888\"/>\n", L, T,
      pw, ph);
  for (int k = 0; k <= 4; ++k) {
    double xv = x0 + (x1 - x0) * k / 4, yv = y0 + (y1 - y0) * k / 4;
    o += fmt::format(
        "<line x1=\"{0:.1f}\" y1=\"{1}\" x2=\"{0:.1f}\" y2=\"{2}\" stroke=\"#eee\"/>"
        "<text x=\"{0:.1f}\" y=\"{3}\" text-anchor=\"middle\">{4:.3g}</text>\n",
        sx(xv), T, T + ph, T + ph + 14, xv);
    o += fmt::format(
        "<line x1=\"{0}\" y1=\"{1:.1f}\" x2=\"{2}\" y2=\"{1:.1f}\" stroke=\"#eee\"/>"
        "<text x=\"{3}\" y=\"{4:.1f}\" text-anchor=\"end\">{5:.3g}</text>\n",
        L, sy(yv), L + pw, L - 4, sy(yv) + 4, yv);
  }
  o += fmt::format("<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{}</text>\n", L + pw / 2, H - 8,
                   html_escape(x_label));
  o += fmt::format(
      "<text x=\"14\" y=\"{0}\" text-anchor=\"middle\" transform=\"rotate(-90 14 "
      "{0})\">{1}</text>\n",
      T + ph / 2, html_escape(y_label));
  for (size_t s = 0; s < series.size(); ++s) {
    const char* col = kColours[s % 8];
    std::string pts;
    for (size_t i = 0; i < std::min(series[s].x.size(), series[s].y.size()); ++i)
      if (std::isfinite(series[s].x[i]) && std::isfinite(series[s].y[i]))
        pts += fmt::format("{:.1f},{:.1f} ", sx(series[s].x[i]), sy(series[s].y[i]));
    o += fmt::format(
        "<polyline class=\"series\" fill=\"none\" stroke=\"{}\" stroke-width=\"1.5\" "
        "points=\"{}\"/>\n",
        col, pts);
    o += fmt::format(
        "<rect x=\"{}\" y=\"{}\" width=\"10\" height=\"3\" fill=\"{}\"/><text x=\"{}\" "
        "y=\"{}\">{}</text>\n",
        L + 8, T + 10 + 14 * s, col, L + 22, T + 14 + 14 * s, html_escape(series[s].name));
  }
  o += "</svg>\n";
  return o;
}

std::vector<unsigned char> depth_colour_bar_png(int width, int height) {
  CVD_CHECK(width > 1 && height > 0, "depth_colour_bar_png: bad size {}x{}", width, height);
  cv::Mat grey(height, width, CV_8U);
  for (int x = 0; x < width; ++x)  // near (left) to far (right), as the thumbnails colour them
    grey.col(x).setTo(uint8_t(std::lround(255.0 * (1.0 - double(x) / (width - 1)))));
  cv::Mat colour;
  cv::applyColorMap(grey, colour, cv::COLORMAP_TURBO);
  std::vector<unsigned char> png;
  if (!cv::imencode(".png", colour, png))
    fail(ErrorCategory::internal, "depth_colour_bar_png: PNG encoding failed");
  return png;
}

std::vector<unsigned char> depth_thumbnail_png(const cv::Mat& depth, double lo, double hi,
                                               int max_width) {
  CVD_CHECK(depth.type() == CV_32F, "depth_thumbnail_png: depth must be CV_32F");
  cv::Mat small = depth;
  if (depth.cols > max_width) {
    int h = std::max(1, int(std::lround(depth.rows * double(max_width) / depth.cols)));
    cv::resize(depth, small, cv::Size(max_width, h), 0, 0, cv::INTER_NEAREST);
  }
  if (!(hi > lo)) hi = lo + 1;
  cv::Mat grey(small.size(), CV_8U), invalid(small.size(), CV_8U);
  for (int y = 0; y < small.rows; ++y)
    for (int x = 0; x < small.cols; ++x) {
      float d = small.at<float>(y, x);
      bool ok = std::isfinite(d) && d > 0;
      double t = ok ? std::clamp((hi - d) / (hi - lo), 0.0, 1.0) : 0.0;  // near = 1
      grey.at<uint8_t>(y, x) = uint8_t(std::lround(t * 255));
      invalid.at<uint8_t>(y, x) = ok ? 0 : 255;
    }
  cv::Mat colour;
  cv::applyColorMap(grey, colour, cv::COLORMAP_TURBO);
  colour.setTo(cv::Scalar(0, 0, 0), invalid);
  std::vector<unsigned char> png;
  if (!cv::imencode(".png", colour, png))
    fail(ErrorCategory::internal, "depth_thumbnail_png: PNG encoding failed");
  return png;
}

// ---- the page -----------------------------------------------------------------------------------

static std::string num(const nlohmann::json& j, const char* key, const char* f = "{:.4g}") {
  if (!j.contains(key) || !j[key].is_number()) return "&ndash;";
  return fmt::format(fmt::runtime(f), j[key].get<double>());
}

static std::vector<double> doubles(const nlohmann::json& j) {
  std::vector<double> v;
  if (j.is_array())
    for (auto& e : j) v.push_back(e.is_number() ? e.get<double>() : NAN);
  return v;
}

static std::vector<double> iota_like(size_t n, double scale = 1.0) {
  std::vector<double> v(n);
  for (size_t i = 0; i < n; ++i) v[i] = n > 1 ? double(i) * scale : 0.0;
  return v;
}

static std::string depth_section(const nlohmann::json& depth) {
  std::string o =
      "<h2>Depth accuracy</h2>\n<table><tr><th>alignment</th><th>space</th>"
      "<th>AbsRel</th><th>SqRel</th><th>RMSE</th><th>RMSE log</th>"
      "<th>&delta;&lt;1.25</th><th>&delta;&lt;1.25&sup2;</th>"
      "<th>&delta;&lt;1.25&sup3;</th><th>frames</th></tr>\n";
  for (auto& [align, spaces] : depth.items())
    for (auto& [space, m] : spaces.items())
      o += fmt::format(
          "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>"
          "<td>{}</td><td>{}</td><td>{}</td></tr>\n",
          html_escape(align), html_escape(space), num(m, "abs_rel"), num(m, "sq_rel"),
          num(m, "rmse"), num(m, "rmse_log"), num(m, "delta1"), num(m, "delta2"), num(m, "delta3"),
          num(m, "frames", "{:.0f}"));
  o += "</table>\n<p class=\"note\">Depth-space metrics are in the GT's unit (metres); "
       "disparity-space ones in 1/unit. Means over frames. The plots show the aligned rows; "
       "the unaligned (none) ones are in the table only.</p>\n";
  for (const char* space : {"depth", "disparity"}) {
    std::vector<PlotSeries> sorted, per_frame;
    for (auto& [align, spaces] : depth.items()) {
      // Unaligned errors are orders of magnitude apart from aligned ones: table only, so the
      // plots show the aligned curves on their own scale.
      if (!spaces.contains(space) || align == "none") continue;
      const auto& m = spaces[space];
      std::vector<double> e = doubles(m.value("sorted_abs_rel", nlohmann::json::array()));
      sorted.push_back({align, iota_like(e.size(), e.size() > 1 ? 100.0 / (e.size() - 1) : 0), e});
      std::vector<double> f = doubles(m.value("per_frame_abs_rel", nlohmann::json::array()));
      per_frame.push_back({align, iota_like(f.size()), f});
    }
    if (sorted.empty()) continue;
    o += "<div class=\"row\">";
    o += svg_line_plot(fmt::format("Sorted per-pixel AbsRel ({})", space), "pixels (%)", "AbsRel",
                       sorted);
    o += svg_line_plot(fmt::format("AbsRel per frame ({})", space), "frame", "AbsRel", per_frame);
    o += "</div>\n";
  }
  return o;
}

// The median_frame errors on low-texture pixels and the rest (eval_texture_split.h).
static std::string texture_section(const nlohmann::json& t) {
  std::string o =
      "<table><tr><th>pixels (median per frame, depth)</th><th>share</th><th>AbsRel</th>"
      "<th>&delta;&lt;1.25</th></tr>\n";
  for (const char* region : {"low_texture", "textured"}) {
    const nlohmann::json r = t.value(region, nlohmann::json::object());
    o += fmt::format("<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>\n",
                     region == std::string("textured") ? "textured" : "low texture",
                     num(r, "share", "{:.3f}"), num(r, "abs_rel"), num(r, "delta1"));
  }
  o += fmt::format(
      "</table>\n<p class=\"note\">Low texture: 3x3 Sobel gradient under {} grey levels on the "
      "frame brought to {} px; untrained depth errs most there (flow is least reliable on flat "
      "image regions).</p>\n",
      num(t, "threshold", "{:.0f}"), num(t, "long_side", "{:.0f}"));
  return o;
}

static std::string pose_section(const nlohmann::json& pose) {
  std::string o =
      "<h2>Camera trajectory</h2>\n<table><tr><th>ATE RMSE</th><th>ATE mean</th>"
      "<th>ATE median</th><th>ATE max</th><th>Sim(3) scale</th><th>frames</th></tr>\n";
  o += fmt::format(
      "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>"
      "</table>\n",
      num(pose, "ate_rmse"), num(pose, "ate_mean"), num(pose, "ate_median"), num(pose, "ate_max"),
      num(pose.value("sim3", nlohmann::json::object()), "scale"), num(pose, "frames", "{:.0f}"));
  o += "<table><tr><th>RPE &Delta; (frames)</th><th>trans RMSE</th><th>trans mean</th>"
       "<th>rot mean (deg)</th><th>rot RMSE (deg)</th><th>motion direction mean (deg)</th>"
       "<th>pairs</th></tr>\n";
  for (auto& r : pose.value("rpe", nlohmann::json::array()))
    o += fmt::format(
        "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>\n",
        num(r, "delta", "{:.0f}"), num(r, "trans_rmse"), num(r, "trans_mean"),
        num(r, "rot_mean_deg"), num(r, "rot_rmse_deg"), num(r, "dir_mean_deg"),
        num(r, "pairs", "{:.0f}"));
  o += "</table>\n<div class=\"row\">";
  if (pose.contains("trajectory")) {
    std::vector<PlotSeries> top;
    for (const char* k : {"gt", "est_aligned"}) {
      PlotSeries s{k == std::string("gt") ? "ground truth" : "estimate (Sim(3)-aligned)", {}, {}};
      for (auto& p : pose["trajectory"].value(k, nlohmann::json::array())) {
        s.x.push_back(p[0].get<double>());
        s.y.push_back(p[2].get<double>());
      }
      top.push_back(s);
    }
    o += svg_line_plot("Trajectory, top view (x-z)", "x", "z", top, true);
  }
  std::vector<double> ate = doubles(pose.value("ate_per_frame", nlohmann::json::array()));
  o += svg_line_plot("Position error per frame", "frame", "ATE",
                     {{"ATE", iota_like(ate.size()), ate}});
  o += "</div>\n";
  return o;
}

static std::string consistency_section(const nlohmann::json& c) {
  std::string o = "<h2>Geometric consistency (no GT needed)</h2>\n";
  if (c.contains("skipped")) {
    return o + fmt::format("<p class=\"note\">Skipped: {}</p>\n",
                           html_escape(c["skipped"].get<std::string>()));
  }
  o += "<table><tr><th>instability E<sub>s</sub></th><th>drift E<sub>d</sub></th>"
       "<th>spread about centroid</th><th>covariance eigenvalue ratio (median)</th><th>tracks</th>"
       "<th>flow reprojection (px)</th><th>flow pairs</th></tr>\n";
  o += fmt::format(
      "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>"
      "<td>{}</td></tr></table>\n",
      num(c, "instability"), num(c, "drift"), num(c, "instability_centroid"),
      num(c, "drift_eigen_ratio"), num(c, "tracks", "{:.0f}"), num(c, "flow_reprojection_px"),
      num(c, "flow_pairs", "{:.0f}"));
  std::vector<double> pp = doubles(c.value("per_pair_px", nlohmann::json::array()));
  if (!pp.empty())
    o += svg_line_plot("Flow reprojection error per consecutive pair", "pair (i, i+1)",
                       "mean |p_ij - f_ij| (px)", {{"pairs", iota_like(pp.size()), pp}});
  return o;
}

std::string render_eval_report(const nlohmann::json& m,
                               const std::vector<ReportThumbnail>& thumbnails) {
  std::string o =
      "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
      "<title>cvd eval report</title>\n<style>body{font-family:sans-serif;margin:24px;"
      "max-width:1200px}table{border-collapse:collapse;margin:8px 0}td,th{border:1px solid #ccc;"
      "padding:3px 8px;text-align:right}th{background:#f4f4f4}.row{display:flex;flex-wrap:wrap;"
      "gap:12px}.note{color:#555;font-size:90%}figure{margin:4px}figcaption{font-size:85%}"
      "</style></head><body>\n<h1>cvd eval report</h1>\n";
  o += fmt::format(
      "<p>prediction: <code>{}</code><br>ground truth: <code>{}</code></p>\n",
      html_escape(m.value("pred", "")),
      html_escape(m.contains("gt") && m["gt"].is_string() ? m["gt"].get<std::string>() : "none"));
  if (m.contains("frames"))
    o += fmt::format("<p>frames: prediction {}, ground truth {}, matched {}</p>\n",
                     num(m["frames"], "pred", "{:.0f}"), num(m["frames"], "gt", "{:.0f}"),
                     num(m["frames"], "matched", "{:.0f}"));
  if (m.contains("depth") && !m["depth"].empty()) o += depth_section(m["depth"]);
  if (m.contains("pose")) o += pose_section(m["pose"]);
  if (m.contains("consistency")) o += consistency_section(m["consistency"]);
  if (!thumbnails.empty()) {
    o += "<h2>Depth</h2>\n";
    if (m.contains("thumbnail_depth_range") && m["thumbnail_depth_range"].size() == 2) {
      // One colour range for every thumbnail (predictions scaled to the GT's), so one bar.
      const auto& r = m["thumbnail_depth_range"];
      o += fmt::format(
          "<figure class=\"colourbar\"><div style=\"display:flex;align-items:center;gap:6px\">"
          "<span>{:.3g}</span><img alt=\"depth colour bar\" width=\"256\" height=\"12\" "
          "src=\"data:image/png;base64,{}\"><span>{:.3g}</span></div><figcaption>depth, near "
          "to far (every thumbnail below)</figcaption></figure>\n",
          r[0].get<double>(), base64_encode(depth_colour_bar_png(256, 12)), r[1].get<double>());
    }
    o += "<div class=\"row\">";
    for (auto& t : thumbnails)
      o += fmt::format(
          "<figure><img alt=\"{0}\" src=\"data:image/png;base64,{1}\">"
          "<figcaption>{0}</figcaption></figure>\n",
          html_escape(t.caption), base64_encode(t.png));
    o += "</div>\n";
  }
  if (m.contains("depth_by_texture")) {
    o += "<h2>Depth by texture</h2>\n";
    o += texture_section(m["depth_by_texture"]);
  }
  for (auto& n : m.value("notes", nlohmann::json::array()))
    o += fmt::format("<p class=\"note\">{}</p>\n", html_escape(n.get<std::string>()));
  o += "</body></html>\n";
  return o;
}

void write_eval_report(const std::filesystem::path& path, const nlohmann::json& metrics,
                       const std::vector<ReportThumbnail>& thumbnails) {
  write_text_file(path, render_eval_report(metrics, thumbnails));
}

}  // namespace cvd
