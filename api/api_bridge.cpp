#include "api/api_bridge.h"

#include <filesystem>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace cvd::api_bridge {

cv::Mat bgr_from_view(const v1::ImageView& v, const char* what) {
  CVD_CHECK(v.data != nullptr && v.width > 0 && v.height > 0, "{}: empty image ({}x{})", what,
            v.width, v.height);
  CVD_CHECK(v.channels == 1 || v.channels == 3 || v.channels == 4,
            "{}: {} channels; expected 1 (gray), 3 (RGB) or 4 (RGBA)", what, v.channels);
  const size_t packed = size_t(v.width) * v.channels;
  const size_t stride = v.stride_bytes == 0 ? packed : v.stride_bytes;
  CVD_CHECK(stride >= packed, "{}: stride {} bytes is less than width * channels = {}", what,
            stride, packed);
  const cv::Mat wrapped(v.height, v.width, CV_8UC(v.channels), const_cast<uint8_t*>(v.data),
                        stride);
  cv::Mat bgr;
  if (v.channels == 3) cv::cvtColor(wrapped, bgr, cv::COLOR_RGB2BGR);
  if (v.channels == 1) cv::cvtColor(wrapped, bgr, cv::COLOR_GRAY2BGR);
  if (v.channels == 4) cv::cvtColor(wrapped, bgr, cv::COLOR_RGBA2BGR);
  return bgr;
}

v1::Image image_from_bgr(const cv::Mat& bgr) {
  cv::Mat rgb;
  if (bgr.channels() == 1) {
    rgb = bgr;
  } else {
    cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  }
  v1::Image out(rgb.cols, rgb.rows, rgb.channels());
  for (int y = 0; y < rgb.rows; ++y)
    std::copy(rgb.ptr<uint8_t>(y), rgb.ptr<uint8_t>(y) + size_t(rgb.cols) * rgb.channels(),
              out.pixels.begin() + size_t(y) * rgb.cols * rgb.channels());
  return out;
}

v1::DepthMap depth_map_from_mat(const cv::Mat& depth) {
  CVD_ASSERT(depth.type() == CV_32F);
  v1::DepthMap d;
  d.width = depth.cols;
  d.height = depth.rows;
  d.depth.resize(size_t(depth.cols) * depth.rows);
  for (int y = 0; y < depth.rows; ++y)
    std::copy(depth.ptr<float>(y), depth.ptr<float>(y) + depth.cols,
              d.depth.begin() + size_t(y) * depth.cols);
  return d;
}

CoreIntrinsics to_core(const v1::CameraIntrinsics& k) {
  return CoreIntrinsics{k.fx, k.fy, k.cx, k.cy, k.width, k.height};
}

v1::CameraIntrinsics to_public(const CoreIntrinsics& k) {
  return v1::CameraIntrinsics{k.fx, k.fy, k.cx, k.cy, k.width, k.height};
}

}  // namespace cvd::api_bridge

namespace cvd::v1 {

Image read_image(const std::string& path) {
  const cv::Mat bgr = cv::imread(path, cv::IMREAD_COLOR);
  if (bgr.empty())
    fail(ErrorCategory::io, "{}: cannot read the image (missing or not an image)", path);
  return api_bridge::image_from_bgr(bgr);
}

void write_image(const std::string& path, const Image& image) {
  cv::Mat bgr = api_bridge::bgr_from_view(image.view(), path.c_str());
  if (image.channels == 1) cv::cvtColor(bgr, bgr, cv::COLOR_BGR2GRAY);
  // Written under a temporary name (same extension, so the same format) and renamed when complete.
  const std::filesystem::path final_path(path);
  std::filesystem::path tmp = final_path;
  std::string tmp_name = final_path.stem().string();
  tmp_name.insert(tmp_name.begin(), '.');
  tmp_name += ".tmp";
  tmp_name += final_path.extension().string();
  tmp.replace_filename(tmp_name);
  bool ok = false;
  try {
    ok = cv::imwrite(tmp.string(), bgr);
  } catch (const cv::Exception& e) {
    fail(ErrorCategory::io, "{}: cannot write the image: {}", path, e.what());
  }
  if (!ok)
    fail(ErrorCategory::io, "{}: cannot write the image (unknown extension or unwritable)", path);
  std::error_code ec;
  std::filesystem::rename(tmp, final_path, ec);
  if (ec)
    fail(ErrorCategory::io, "{}: cannot rename the written image into place: {}", path,
         ec.message());
}

const char* version() { return CVD_VERSION; }

}  // namespace cvd::v1

namespace cvd::api_bridge {
// cvd::error_category_name (engine/error.cpp, declared in the public cvd/error.h) is part of the
// public API; nothing in api/ calls it, so keep a reference that makes the linker pull it into
// libcvd.so (api/libcvd.map exports it).
[[gnu::used]] const char* (*const keep_error_category_name)(ErrorCategory) = &error_category_name;
}  // namespace cvd::api_bridge
