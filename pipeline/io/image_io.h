// 8-bit image files (PNG, JPEG, ... as OpenCV decodes them): reading with clear errors and
// atomic writing. Colour images are CV_8UC3 in OpenCV's B, G, R channel order.
#pragma once
#include <opencv2/core.hpp>

#include <filesystem>

namespace cvd {

// Reads a colour image as CV_8UC3 (BGR); grey inputs are expanded, alpha is dropped, EXIF
// orientation is applied. Throws Error(io) when the file is missing or unreadable and
// Error(format) when OpenCV cannot decode it; both name the file.
cv::Mat read_color_image(const std::filesystem::path& path);

// Reads a single-channel image unchanged in depth (CV_8UC1 or CV_16UC1, e.g. masks or 16-bit
// depth PNGs). Throws Error(format) when it does not decode or has more than one channel.
cv::Mat read_single_channel_image(const std::filesystem::path& path);

// Writes an image with the encoder chosen by the extension of `path` (".png", ".jpg", ...), to a
// temporary name in the same folder, renamed when complete. Throws Error(invalid_argument) for an
// empty image and Error(io) when encoding or writing fails.
void write_image(const std::filesystem::path& path, const cv::Mat& image);

}  // namespace cvd
