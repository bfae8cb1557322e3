#include "pipeline/io/frame_source.h"

#include <spdlog/spdlog.h>

#include <fmt/format.h>
#include <algorithm>
#include <cmath>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include "engine/error.h"

namespace cvd {

namespace fs = std::filesystem;

namespace {

bool is_image_extension(std::string ext) {
  std::transform(ext.begin(), ext.end(), ext.begin(), ::tolower);
  for (const char* e : {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".ppm", ".pgm"})
    if (ext == e) return true;
  return false;
}

bool selected(int index, const FrameSourceOptions& o, int kept) {
  if (index < o.first) return false;
  if ((index - o.first) % std::max(1, o.step) != 0) return false;
  return o.max_frames <= 0 || kept < o.max_frames;
}

void check_size(FrameSourceInfo& info, const cv::Mat& img, const std::string& what) {
  if (info.width == 0) {
    info.width = img.cols;
    info.height = img.rows;
  } else if (img.cols != info.width || img.rows != info.height) {
    fail(
        ErrorCategory::invalid_argument,
        "{}: frame size {}x{} differs from the first frame's {}x{} (all frames must have one size)",
        what, img.cols, img.rows, info.width, info.height);
  }
}

}  // namespace

cv::Size aligned_size(int width, int height, int long_side, int alignment) {
  CVD_CHECK(width > 0 && height > 0 && long_side > 0 && alignment > 0, "bad size request");
  double s = double(long_side) / std::max(width, height);
  auto round_to = [&](double v) {
    return std::max(alignment, static_cast<int>(std::lround(v / alignment)) * alignment);
  };
  return {round_to(width * s), round_to(height * s)};
}

FrameSourceInfo read_frames(
    const fs::path& input, const FrameSourceOptions& o,
    const std::function<void(int, const std::string&, const cv::Mat&)>& sink) {
  FrameSourceInfo info;
  std::error_code ec;
  if (!fs::exists(input, ec))
    fail(ErrorCategory::io, "{}: no such file or directory", input.string());
  int kept = 0;
  if (fs::is_directory(input)) {
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(input)) {
      if (!e.is_regular_file()) continue;
      if (is_image_extension(e.path().extension().string()))
        files.push_back(e.path());
      else if (e.path().filename().string()[0] != '.')
        info.skipped_files.push_back(e.path().filename().string());
    }
    std::sort(files.begin(), files.end());
    if (!info.skipped_files.empty())
      spdlog::warn("{}: ignoring {} non-image file(s), e.g. '{}'", input.string(),
                   info.skipped_files.size(), info.skipped_files[0]);
    if (files.empty())
      fail(ErrorCategory::invalid_argument, "{}: the folder holds no images", input.string());
    for (int i = 0; i < static_cast<int>(files.size()); ++i) {
      if (!selected(i, o, kept)) continue;
      cv::Mat img = cv::imread(files[i].string(), cv::IMREAD_COLOR);  // applies EXIF orientation
      if (img.empty())
        fail(ErrorCategory::format, "{}: cannot decode the image (corrupt or unsupported format)",
             files[i].string());
      check_size(info, img, files[i].string());
      std::string name = files[i].stem().string();
      info.names.push_back(name);
      sink(kept++, name, img);
    }
  } else {
    cv::VideoCapture cap(input.string(), cv::CAP_FFMPEG);
    if (!cap.isOpened())
      fail(ErrorCategory::format, "{}: cannot open the video (not a video file, or corrupt)",
           input.string());
    info.is_video = true;
    double fps = cap.get(cv::CAP_PROP_FPS);
    if (fps > 0 && std::isfinite(fps)) info.fps = fps;
    cv::Mat img;
    for (int i = 0; cap.read(img); ++i) {
      if (img.empty()) continue;
      if (o.max_frames > 0 && kept >= o.max_frames) break;
      if (!selected(i, o, kept)) continue;
      check_size(info, img, fmt::format("{} (frame {})", input.string(), i));
      std::string name = fmt::format("frame_{:06d}", i);
      info.names.push_back(name);
      sink(kept++, name, img);
    }
    if (kept == 0)
      fail(ErrorCategory::format, "{}: the video has no decodable frames", input.string());
  }
  if (kept < 2)
    fail(ErrorCategory::invalid_argument,
         "{}: {} frame(s) selected; consistent video depth needs at least 2", input.string(), kept);
  return info;
}

}  // namespace cvd
