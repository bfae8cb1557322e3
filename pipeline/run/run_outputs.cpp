#include "pipeline/run/run_outputs.h"

#include <spdlog/spdlog.h>

#include <fmt/format.h>
#include <algorithm>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "engine/error.h"
#include "pipeline/io/atomic_file.h"
#include "pipeline/io/npy_io.h"
#include "pipeline/io/pfm_io.h"
#include "pipeline/io/trajectory_io.h"

namespace cvd {

namespace fs = std::filesystem;

namespace {

void write_png(const fs::path& p, const cv::Mat& m) {
  write_atomically(p, [&](const fs::path& tmp) {
    if (!cv::imwrite(tmp.string(), m))
      fail(ErrorCategory::io, "{}: cannot write the image", p.string());
  });
}

}  // namespace

std::pair<double, double> video_inverse_depth_range(const std::vector<cv::Mat>& depths) {
  std::vector<float> inv;
  for (const auto& d : depths)
    for (int y = 0; y < d.rows; y += 2)
      for (int x = 0; x < d.cols; x += 2) {
        float z = d.at<float>(y, x);
        if (z > 0 && std::isfinite(z)) inv.push_back(1.0f / z);
      }
  if (inv.empty()) return {0.0, 1.0};
  std::sort(inv.begin(), inv.end());
  double lo = inv[inv.size() * 2 / 100], hi = inv[std::min(inv.size() - 1, inv.size() * 98 / 100)];
  if (hi <= lo) hi = lo + 1e-6;
  return {lo, hi};
}

cv::Mat colorize_depth(const cv::Mat& depth, std::pair<double, double> r) {
  cv::Mat u8(depth.size(), CV_8U);
  for (int y = 0; y < depth.rows; ++y)
    for (int x = 0; x < depth.cols; ++x) {
      float z = depth.at<float>(y, x);
      double v = z > 0 && std::isfinite(z) ? (1.0 / z - r.first) / (r.second - r.first) : 0.0;
      u8.at<uint8_t>(y, x) = static_cast<uint8_t>(std::clamp(v, 0.0, 1.0) * 255.0 + 0.5);
    }
  cv::Mat color;
  cv::applyColorMap(u8, color, cv::COLORMAP_TURBO);
  return color;
}

void write_depth_maps(const fs::path& out, const RunOutputs& r,
                      const std::vector<std::string>& formats) {
  auto wants = [&](const char* f) {
    return std::find(formats.begin(), formats.end(), f) != formats.end();
  };
  for (const std::string& f : formats)
    CVD_CHECK(f == "pfm" || f == "png16" || f == "color" || f == "npy",
              "unknown depth format '{}' (expected pfm, png16, color or npy)", f);
  if (wants("pfm")) fs::create_directories(out / "depth");
  if (wants("png16")) fs::create_directories(out / "depth_png16");
  if (wants("color")) fs::create_directories(out / "depth_color");
  double max_depth = 0;
  for (const auto& d : r.depths) {
    double mn, mx;
    cv::minMaxLoc(d, &mn, &mx);
    max_depth = std::max(max_depth, mx);
  }
  double per_unit = max_depth > 0 ? max_depth / 65535.0 : 1.0;
  auto range = video_inverse_depth_range(r.depths);
  for (size_t k = 0; k < r.names.size(); ++k) {
    if (wants("pfm")) write_pfm(out / "depth" / (r.names[k] + ".pfm"), r.depths[k]);
    if (wants("png16")) {
      cv::Mat u16;
      r.depths[k].convertTo(u16, CV_16U, 1.0 / per_unit);
      write_png(out / "depth_png16" / (r.names[k] + ".png"), u16);
    }
    if (wants("color"))
      write_png(out / "depth_color" / (r.names[k] + ".png"), colorize_depth(r.depths[k], range));
  }
  if (wants("png16")) {
    nlohmann::json s = {{"depth_per_unit", per_unit},
                        {"formula", "depth = value * depth_per_unit; value 0 = invalid"},
                        {"units", "the run's pose units (see run.json)"},
                        {"color_inverse_depth_range", {range.first, range.second}}};
    write_text_file(out / "depth_png16" / "scale.json", s.dump(2));
  }
  if (wants("npy")) {
    write_npy_stack(out / "depth.npy", r.depths);
    std::string names;
    for (const std::string& n : r.names) names += n + "\n";
    write_text_file(out / "frames.txt", names);
  }
}

void write_cameras(const fs::path& out, const RunOutputs& r) {
  std::vector<TimedPose> traj;
  std::vector<NamedCamera> reg;
  for (size_t k = 0; k < r.cameras.size(); ++k) {
    if (!r.cameras[k].registered) continue;
    traj.push_back({r.timestamps.empty() ? static_cast<double>(k) / r.fps : r.timestamps.at(k),
                    r.cameras[k].pose});
    reg.push_back(r.cameras[k]);
  }
  write_tum_trajectory(out / "poses.txt", traj);
  fs::create_directories(out / "colmap");
  write_colmap_text_model(out / "colmap", colmap_model_from_frames(reg));
  if (!r.cameras.empty()) write_intrinsics_json(out / "intrinsics.json", r.cameras[0].intrinsics);
}

std::vector<FusedPoint> fuse_point_cloud(const RunOutputs& r, int pixel_step, int frame_step) {
  CVD_CHECK(pixel_step > 0 && frame_step > 0, "fuse_point_cloud: steps must be positive ({}, {})",
            pixel_step, frame_step);
  std::vector<FusedPoint> points;
  for (size_t k = 0; k < r.names.size(); k += frame_step) {
    const NamedCamera& c = r.cameras[k];
    if (!c.registered) continue;
    const cv::Mat& d = r.depths[k];
    const Intrinsics& K = c.intrinsics;
    for (int y = 0; y < d.rows; y += pixel_step)
      for (int x = 0; x < d.cols; x += pixel_step) {
        float z = d.at<float>(y, x);
        if (!(z > 0) || !std::isfinite(z)) continue;
        Eigen::Vector3d pc((x - K.cx) / K.fx * z, (y - K.cy) / K.fy * z, z);
        cv::Vec3b bgr =
            r.frames_bgr.empty() ? cv::Vec3b(200, 200, 200) : r.frames_bgr[k].at<cv::Vec3b>(y, x);
        points.push_back({c.pose.transform(pc), cv::Vec3b(bgr[2], bgr[1], bgr[0])});
      }
  }
  return points;
}

void write_point_cloud(const fs::path& file, const RunOutputs& r, int pixel_step, int frame_step) {
  std::string body;
  std::vector<FusedPoint> points = fuse_point_cloud(r, pixel_step, frame_step);
  for (const FusedPoint& p : points)
    body += fmt::format("{:.5f} {:.5f} {:.5f} {} {} {}\n", p.position.x(), p.position.y(),
                        p.position.z(), p.rgb[0], p.rgb[1], p.rgb[2]);
  std::string header = fmt::format(
      "ply\nformat ascii 1.0\ncomment cvd fused point cloud (every {} px of every {}th frame)\n"
      "element vertex {}\nproperty float x\nproperty float y\nproperty float z\n"
      "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n",
      pixel_step, frame_step, points.size());
  write_text_file(file, header + body);
}

void write_videos(const fs::path& out, const RunOutputs& r) {
  if (r.depths.empty()) return;
  auto range = video_inverse_depth_range(r.depths);
  cv::Size s = r.depths[0].size();
  auto write = [&](const fs::path& target, bool side_by_side) {
    write_atomically(target, [&](const fs::path& tmp) {
      cv::Size vs = side_by_side ? cv::Size(2 * s.width, s.height) : s;
      cv::VideoWriter w(tmp.string(), cv::VideoWriter::fourcc('m', 'p', '4', 'v'), r.fps, vs);
      if (!w.isOpened())
        fail(ErrorCategory::io, "{}: cannot open a video writer (mp4v)", target.string());
      for (size_t k = 0; k < r.depths.size(); ++k) {
        cv::Mat c = colorize_depth(r.depths[k], range);
        if (side_by_side) {
          cv::Mat both;
          cv::hconcat(r.frames_bgr[k], c, both);
          w.write(both);
        } else {
          w.write(c);
        }
      }
      w.release();
    });
  };
  write(out / "depth.mp4", false);
  if (!r.frames_bgr.empty()) write(out / "side_by_side.mp4", true);
}

const std::vector<std::string>& run_output_names() {
  static const std::vector<std::string> names = {
      "depth",     "depth_png16",      "depth_color",         "depth_initial",
      "poses.txt", "colmap",           "intrinsics.json",     "points.ply",
      "depth.mp4", "side_by_side.mp4", "sparse_depth.csv.gz", "sparse_depth.csv",
      "run.json",  "depth.npy",        "frames.txt",          "viewer.html"};
  return names;
}

PartialOutputsGuard::~PartialOutputsGuard() {
  if (committed_) return;
  for (const auto& name : run_output_names()) {
    std::error_code ec;
    fs::remove_all(out_ / name, ec);
    if (ec)
      spdlog::warn("{}: cannot remove the partial output: {}", (out_ / name).string(),
                   ec.message());
  }
}

}  // namespace cvd
