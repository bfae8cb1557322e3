// NumPy .npy arrays of float32 depth maps, for Python users (`np.load("depth.npy")`): one file
// holding every frame, shape (N, H, W), little-endian float32, C order (format version 1.0).
#pragma once
#include <filesystem>
#include <opencv2/core.hpp>
#include <vector>

namespace cvd {

// Writes the CV_32F maps (all of one size) as one (N, H, W) array, atomically.
void write_npy_stack(const std::filesystem::path& file, const std::vector<cv::Mat>& maps);

struct NpyStackInfo {
  int64_t frames = 0, height = 0, width = 0;
  size_t data_offset = 0;  // bytes from the start of the file to the first element
};

// Reads and checks the header of a float32 (N, H, W) array; Error(format) naming the file and
// what is wrong (another dtype, Fortran order, another rank, a truncated file).
NpyStackInfo read_npy_stack_info(const std::filesystem::path& file);

// Frame `index` of such an array (reads only that frame).
cv::Mat read_npy_frame(const std::filesystem::path& file, int64_t index);

}  // namespace cvd
