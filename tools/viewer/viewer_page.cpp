// The viewer page of a finished run (see viewer_page.h).
#include "tools/viewer/viewer_page.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "engine/error.h"
#include "pipeline/eval/eval_readers.h"
#include "pipeline/eval/eval_report.h"
#include "pipeline/io/atomic_file.h"
#include "pipeline/run/run_outputs.h"
#include "tools/viewer/viewer_bundle.h"

namespace cvd {
namespace fs = std::filesystem;

namespace {

std::optional<nlohmann::json> read_json_if_present(const fs::path& file) {
  if (!fs::exists(file)) return std::nullopt;
  std::ifstream in(file);
  if (!in) fail(ErrorCategory::io, "{}: cannot open", file.string());
  try {
    return nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    fail(ErrorCategory::format, "{}: not valid JSON ({})", file.string(), e.what());
  }
}

std::string jpeg_base64_url(const cv::Mat& bgr, int width) {
  cv::Mat small = bgr;
  if (bgr.cols > width) {
    int h = std::max(1, static_cast<int>(std::lround(double(bgr.rows) * width / bgr.cols)));
    cv::resize(bgr, small, cv::Size(width, h), 0, 0, cv::INTER_AREA);
  }
  std::vector<unsigned char> bytes;
  if (!cv::imencode(".jpg", small, bytes, {cv::IMWRITE_JPEG_QUALITY, 88}))
    fail(ErrorCategory::internal, "viewer: JPEG encoding failed");
  return "data:image/jpeg;base64," + base64_encode(bytes);
}

template <typename T>
std::string base64_of(const std::vector<T>& values) {
  std::vector<unsigned char> bytes(values.size() * sizeof(T));
  if (!bytes.empty()) std::memcpy(bytes.data(), values.data(), bytes.size());
  return base64_encode(bytes);
}

// The run folder read back: depth maps, cameras at the depth resolution, input frames when the
// cache still has them.
RunOutputs read_run(const fs::path& run_dir, ViewerSummary& summary) {
  EvalSequence seq = read_cvd_run(run_dir);
  if (!seq.intrinsics)
    fail(ErrorCategory::format, "{}: no intrinsics.json (not a finished cvd run?)",
         (run_dir / "intrinsics.json").string());
  if (!seq.has_poses())
    fail(ErrorCategory::format, "{}: poses.txt is missing or has no pose for some frames",
         (run_dir / "poses.txt").string());
  attach_images_by_stem(seq, run_dir / "cache" / "frames");
  RunOutputs r;
  for (const EvalFrame& f : seq.frames) {
    cv::Mat depth = load_eval_depth(f);
    NamedCamera cam;
    cam.name = f.name;
    cam.pose = *f.pose;
    cam.intrinsics = seq.intrinsics->scaled_to(depth.cols, depth.rows);
    r.names.push_back(f.name);
    r.depths.push_back(depth);
    r.cameras.push_back(cam);
  }
  if (seq.has_images()) {
    for (size_t k = 0; k < seq.frames.size(); ++k) {
      cv::Mat img = cv::imread(seq.frames[k].image_path.string(), cv::IMREAD_COLOR);
      if (img.empty())
        fail(ErrorCategory::format, "{}: not a readable image", seq.frames[k].image_path.string());
      cv::resize(img, img, r.depths[k].size(), 0, 0, cv::INTER_AREA);
      r.frames_bgr.push_back(img);
    }
  } else {
    summary.warnings.push_back(
        fmt::format("{}: the input frames are not there (removed cache?): the points are grey and "
                    "the slider shows depth only",
                    (run_dir / "cache" / "frames").string()));
  }
  return r;
}

// Short, readable key figures of run.json and eval/metrics.json; absent keys are skipped.
nlohmann::json key_figures(const fs::path& run_dir, const RunOutputs& r, ViewerSummary& summary) {
  nlohmann::json rows = nlohmann::json::array();
  auto add = [&](const std::string& label, const std::string& value) {
    rows.push_back({label, value});
  };
  size_t registered = 0;
  for (const NamedCamera& c : r.cameras) registered += c.registered;
  add("frames", fmt::format("{} ({} with a pose)", r.names.size(), registered));
  if (!r.depths.empty())
    add("depth maps", fmt::format("{} x {}", r.depths[0].cols, r.depths[0].rows));
  auto run = read_json_if_present(run_dir / "run.json");
  if (!run) {
    summary.warnings.push_back(
        fmt::format("{}: not found: no run figures", (run_dir / "run.json").string()));
  } else {
    const nlohmann::json& j = *run;
    if (j.contains("frame_stats") && j["frame_stats"].contains("input_size"))
      add("input", fmt::format("{} x {}", j["frame_stats"]["input_size"][0].get<int>(),
                               j["frame_stats"]["input_size"][1].get<int>()));
    if (j.contains("poses") && j["poses"].is_object()) {
      std::string source = j["poses"].value("source", "");
      std::string intr = j["poses"].value("intrinsics_source", "");
      add("poses", intr.empty() ? source : fmt::format("{}; intrinsics: {}", source, intr));
    }
    if (j.contains("network") && j["network"].is_string())
      add("network", j["network"].get<std::string>());
    if (j.contains("training") && j["training"].is_object()) {
      const nlohmann::json& t = j["training"];
      std::string s = fmt::format("{} epochs", t.value("epochs", 0));
      if (t.contains("geometric_loss_before") && t.contains("geometric_loss_after"))
        s += fmt::format(", geometric loss {:.4g} -> {:.4g}",
                         t["geometric_loss_before"].get<double>(),
                         t["geometric_loss_after"].get<double>());
      add("test-time training", s);
    }
    if (j.contains("timings_s") && j["timings_s"].is_object()) {
      std::string s;
      for (auto& [stage, secs] : j["timings_s"].items())
        if (stage != "total" && secs.is_number())
          s += fmt::format("{}{} {:.0f} s", s.empty() ? "" : ", ", stage, secs.get<double>());
      if (j["timings_s"].contains("total"))
        s = fmt::format("{:.0f} s ({})", j["timings_s"]["total"].get<double>(), s);
      add("run time", s);
    }
  }
  auto metrics = read_json_if_present(run_dir / "eval" / "metrics.json");
  if (metrics) {
    const nlohmann::json& m = *metrics;
    if (m.contains("depth") && m["depth"].contains("median_frame")) {
      const nlohmann::json& d = m["depth"]["median_frame"]["depth"];
      if (d.contains("abs_rel") && d.contains("delta1"))
        add("depth vs ground truth (cvd eval)",
            fmt::format("AbsRel {:.3f}, delta1 {:.3f} (each frame median-aligned)",
                        d["abs_rel"].get<double>(), d["delta1"].get<double>()));
    }
    if (m.contains("pose") && m["pose"].is_object() && m["pose"].contains("ate_rmse"))
      add("camera path vs ground truth",
          fmt::format("ATE {:.3g} (RMSE, aligned)", m["pose"]["ate_rmse"].get<double>()));
  }
  return rows;
}

// Evenly spaced indices, at most `n` of `count`, first and last included.
std::vector<size_t> evenly_spaced(size_t count, size_t n) {
  std::vector<size_t> idx;
  if (count == 0 || n == 0) return idx;
  if (count <= n) {
    for (size_t k = 0; k < count; ++k) idx.push_back(k);
    return idx;
  }
  for (size_t i = 0; i < n; ++i)
    idx.push_back(n == 1 ? 0
                         : static_cast<size_t>(std::llround(double(i) * (count - 1) / (n - 1))));
  return idx;
}

}  // namespace

nlohmann::json viewer_data(const fs::path& run_dir, const ViewerOptions& o,
                           ViewerSummary& summary) {
  CVD_CHECK(o.max_points > 0 && o.max_frames > 0 && o.thumbnail_width >= 16,
            "viewer: --points and --frames must be positive and --thumbnail-width at least 16");
  RunOutputs r = read_run(run_dir, summary);
  summary.frames = r.names.size();

  // The cloud: every 2nd pixel of enough frames for about twice the budget, then thinned evenly.
  size_t pixels = r.depths.empty() ? 0 : r.depths[0].total() / 4;
  size_t frame_step = 1;
  while (pixels > 0 && r.names.size() / frame_step * pixels > 2 * o.max_points &&
         frame_step < r.names.size())
    ++frame_step;
  std::vector<FusedPoint> fused = fuse_point_cloud(r, 2, static_cast<int>(frame_step));
  std::vector<float> xyz;
  std::vector<uint8_t> rgb;
  size_t keep = std::min(fused.size(), o.max_points);
  for (size_t i = 0; i < keep; ++i) {
    const FusedPoint& p = fused[i * fused.size() / keep];
    for (int c = 0; c < 3; ++c) {
      xyz.push_back(static_cast<float>(p.position[c]));
      rgb.push_back(p.rgb[c]);
    }
  }
  summary.points = keep;
  if (keep == 0) summary.warnings.push_back("no valid depth: the cloud is empty");

  nlohmann::json cameras = nlohmann::json::array();
  for (const NamedCamera& c : r.cameras) {
    if (!c.registered) {
      cameras.push_back(nullptr);
      continue;
    }
    nlohmann::json m = nlohmann::json::array();
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 4; ++j) m.push_back(j < 3 ? c.pose.R(i, j) : c.pose.t[i]);
    const Intrinsics& K = c.intrinsics;
    cameras.push_back({{"c2w", m},
                       {"fx", K.fx},
                       {"fy", K.fy},
                       {"cx", K.cx},
                       {"cy", K.cy},
                       {"width", K.width},
                       {"height", K.height}});
    ++summary.cameras;
  }

  auto range = video_inverse_depth_range(r.depths);
  nlohmann::json frames = nlohmann::json::array();
  std::vector<size_t> shown = evenly_spaced(r.names.size(), o.max_frames);
  for (size_t k : shown) {
    cv::Mat depth_bgr = colorize_depth(r.depths[k], range);
    cv::Mat input = r.frames_bgr.empty()
                        ? cv::Mat(depth_bgr.size(), CV_8UC3, cv::Scalar(40, 40, 40))
                        : r.frames_bgr[k];
    frames.push_back({{"name", r.names[k]},
                      {"index", k},
                      {"image", jpeg_base64_url(input, o.thumbnail_width)},
                      {"depth", jpeg_base64_url(depth_bgr, o.thumbnail_width)}});
  }
  summary.frames_shown = shown.size();
  if (shown.size() < r.names.size())
    summary.warnings.push_back(
        fmt::format("the slider shows {} of the {} frames, evenly spaced "
                    "(--frames raises it)",
                    shown.size(), r.names.size()));

  nlohmann::json figures = key_figures(run_dir, r, summary);
  std::string which =
      frame_step == 1 ? std::string("every frame") : fmt::format("one frame in {}", frame_step);
  figures.push_back({"point cloud", fmt::format("{} points (every 2nd pixel of {})", keep, which)});
  std::string folder = fs::absolute(run_dir).lexically_normal().parent_path().filename().string();
  if (fs::absolute(run_dir).lexically_normal().has_filename())
    folder = fs::absolute(run_dir).lexically_normal().filename().string();
  return {{"title", fmt::format("cvd: {}", folder)},
          {"figures", figures},
          {"warnings", summary.warnings},
          {"points", {{"count", keep}, {"positions", base64_of(xyz)}, {"colors", base64_of(rgb)}}},
          {"cameras", cameras},
          {"frames", frames}};
}

std::string viewer_html(const nlohmann::json& data, std::string_view script) {
  // Neither the data nor the script may end their <script> element early.
  std::string json = data.dump();
  for (size_t p = json.find("</"); p != std::string::npos; p = json.find("</", p + 3))
    json.replace(p, 2, "<\\/");
  CVD_ASSERT(script.find("</script") == std::string_view::npos);
  static const char* head = R"(<!doctype html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>cvd</title>
<style>
  html, body { margin: 0; height: 100%; background: #0f1115; color: #e6e6e6;
    font: 14px/1.4 system-ui, sans-serif; }
  body { display: grid; grid-template-rows: auto 1fr auto; grid-template-columns: 1fr 22rem; }
  header { grid-column: 1 / 3; padding: .5rem 1rem; border-bottom: 1px solid #2a2e37; }
  h1 { font-size: 1.1rem; margin: 0; }
  #view { min-height: 18rem; position: relative; overflow: hidden; }
  #view canvas { display: block; }
  aside { padding: .5rem 1rem; border-left: 1px solid #2a2e37; overflow: auto; }
  table { border-collapse: collapse; width: 100%; }
  th, td { text-align: left; vertical-align: top; padding: .2rem .3rem; border-bottom: 1px solid #22252c; }
  th { color: #9aa3b2; font-weight: normal; width: 40%; }
  #warnings li { color: #f2b134; }
  footer { grid-column: 1 / 3; padding: .5rem 1rem; border-top: 1px solid #2a2e37; }
  #slider { width: 100%; }
  .pair { display: flex; gap: .5rem; justify-content: center; }
  .pair figure { margin: 0; text-align: center; }
  .pair img { max-height: 30vh; max-width: 45vw; }
  figcaption { color: #9aa3b2; }
  .hint { color: #9aa3b2; font-size: .85rem; }
</style></head>
<body>
<header><h1 id="title">cvd</h1>
<span class="hint">drag to orbit, right-drag to pan, wheel to zoom; the red frustum is the frame
on the slider, the yellow line the camera path</span></header>
<div id="view"></div>
<aside><table id="figures"></table><ul id="warnings"></ul></aside>
<footer><input id="slider" type="range" min="0" max="0" value="0" aria-label="frame">
<div id="frame-label"></div>
<div class="pair"><figure><img id="input" alt="input frame"><figcaption>input</figcaption></figure>
<figure><img id="depth" alt="depth"><figcaption>depth (near = warm, one range for the video)</figcaption></figure></div>
</footer>
<script id="cvd-data" type="application/json">)";
  std::string html = head;
  html += json;
  html += "</script>\n<script>";
  html += script;
  html += "</script>\n</body></html>\n";
  return html;
}

bool viewer_available() { return !viewer_bundle_script().empty(); }

ViewerSummary write_viewer(const fs::path& run_dir, const ViewerOptions& o) {
  std::string_view script = viewer_bundle_script();
  if (!viewer_available())
    fail(ErrorCategory::unsupported,
         "this cvd was built without the viewer's script (it needs node and `npm ci --prefix "
         "tools/viewer/web` before cmake; scripts/install-deps.sh does both)");
  ViewerSummary summary;
  nlohmann::json data = viewer_data(run_dir, o, summary);
  summary.file = o.output.empty() ? run_dir / "viewer.html" : o.output;
  std::string html = viewer_html(data, script);
  write_text_file(summary.file, html);
  summary.bytes = html.size();
  return summary;
}

}  // namespace cvd
