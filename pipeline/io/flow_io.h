// Middlebury .flo optical-flow files: read and write as cv::Mat CV_32FC2 (u, v) in pixels.
//
// Layout (little-endian): float32 magic 202021.25, int32 width, int32 height, then
// height * width * 2 float32 values, row-major, interleaved (u, v) per pixel; pixel (x, y) of the
// first image moves to (x + u, y + v) in the second.
#pragma once
#include <opencv2/core.hpp>

#include <filesystem>

namespace cvd {

inline constexpr float kFloMagic = 202021.25f;
// Largest width or height read_flo accepts: guards against allocating from a corrupt header.
inline constexpr int kFloMaxDimension = 1 << 15;

// Reads a .flo file. Throws Error(io) when the file cannot be opened and Error(format) when the
// magic is wrong, a dimension is zero, negative or above kFloMaxDimension, or the file is
// truncated or has trailing bytes. Every message names the file.
cv::Mat read_flo(const std::filesystem::path& path);

// Writes a CV_32FC2 flow as .flo: to a temporary name next to `path`, renamed when complete.
// Throws Error(invalid_argument) for a wrong type or an empty flow, Error(io) on write failure.
void write_flo(const std::filesystem::path& path, const cv::Mat& flow);

}  // namespace cvd
