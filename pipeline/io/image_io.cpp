#include "pipeline/io/image_io.h"

#include <opencv2/imgcodecs.hpp>

#include "engine/error.h"
#include "pipeline/io/atomic_file.h"

namespace cvd {

namespace {

void require_readable(const std::filesystem::path& path, const char* what) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    fail(ErrorCategory::io, "{} '{}' does not exist or is not a file", what, path.string());
}

}  // namespace

cv::Mat read_color_image(const std::filesystem::path& path) {
  require_readable(path, "image");
  cv::Mat image;
  try {
    image = cv::imread(path.string(), cv::IMREAD_COLOR);
  } catch (const cv::Exception& e) {
    fail(ErrorCategory::format, "cannot decode image '{}': {}", path.string(), e.what());
  }
  if (image.empty())
    fail(ErrorCategory::format, "cannot decode image '{}' (corrupt or unsupported format)",
         path.string());
  return image;
}

cv::Mat read_single_channel_image(const std::filesystem::path& path) {
  require_readable(path, "image");
  cv::Mat image;
  try {
    image = cv::imread(path.string(), cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    fail(ErrorCategory::format, "cannot decode image '{}': {}", path.string(), e.what());
  }
  if (image.empty())
    fail(ErrorCategory::format, "cannot decode image '{}' (corrupt or unsupported format)",
         path.string());
  if (image.channels() != 1)
    fail(ErrorCategory::format, "image '{}' has {} channels, expected a single-channel image",
         path.string(), image.channels());
  return image;
}

void write_image(const std::filesystem::path& path, const cv::Mat& image) {
  CVD_CHECK(!image.empty(), "write_image('{}'): image is empty", path.string());
  write_atomically(path, [&](const std::filesystem::path& tmp) {
    bool ok = false;
    try {
      ok = cv::imwrite(tmp.string(), image);
    } catch (const cv::Exception& e) {
      fail(ErrorCategory::io, "cannot write image '{}': {}", path.string(), e.what());
    }
    if (!ok)
      fail(ErrorCategory::io,
           "cannot write image '{}' (unknown extension, disk full or no "
           "permission?)",
           path.string());
  });
}

}  // namespace cvd
