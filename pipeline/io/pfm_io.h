// Portable Float Map (.pfm) files: read and write float32 images as cv::Mat.
//
// Format: ASCII header "Pf" (1 channel) or "PF" (3 channels), whitespace, "<width> <height>",
// whitespace, "<scale>", exactly one whitespace byte, then width * height * channels float32
// values, rows stored from the BOTTOM of the image to the top, channels interleaved. A negative
// scale means little-endian data, a positive one big-endian; its magnitude is not applied.
// Channel order: a 3-channel file holds R, G, B per pixel; a CV_32FC3 Mat is in OpenCV's B, G, R
// order (as cv::imread returns), so read_pfm / write_pfm swap the first and third channels.
#pragma once
#include <opencv2/core.hpp>

#include <filesystem>

namespace cvd {

// Largest width or height read_pfm accepts: guards against allocating from a corrupt header.
inline constexpr int kPfmMaxDimension = 1 << 15;

// Reads a .pfm file into a CV_32FC1 or CV_32FC3 Mat (top row first). Reads both byte orders.
// Throws Error(io) when the file cannot be opened or read, and Error(format) when the header is
// malformed (magic, size, scale), or the data is truncated or followed by extra bytes. Every
// message names the file and the cause. Values are returned as stored (NaN / Inf included).
cv::Mat read_pfm(const std::filesystem::path& path);

// Writes a CV_32FC1 or CV_32FC3 Mat as little-endian PFM (scale -1), to a temporary name next to
// `path` renamed when complete. Throws Error(invalid_argument) for another type or an empty Mat,
// Error(io) when writing fails.
void write_pfm(const std::filesystem::path& path, const cv::Mat& image);

}  // namespace cvd
