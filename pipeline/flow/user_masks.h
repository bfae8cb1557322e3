// User masks of regions to ignore (typically moving objects): one image per frame, named like the
// frame (<name>.png), 0 = ignore, anything else = static scene (COLMAP's mask convention). The
// pipeline passes them to COLMAP's feature extractor and removes the pixels they cover from the
// flow pairs, so moving objects contribute neither sparse points nor geometric-loss terms (the
// paper's loss assumes a static scene; Luo et al. 2020, section 7).
#pragma once
#include <opencv2/core.hpp>

#include <filesystem>
#include <string>
#include <vector>

namespace cvd {

// CV_8U masks at `size`, 255 = usable, 0 = ignored, one per name. A pixel is usable only when
// every input pixel it covers is non-zero (resizing never lets an ignored region shrink). A
// frame without a file gets an all-usable mask. Fails naming the file when the folder is missing
// or a file exists but cannot be decoded. `frames_with_masks` (optional) counts the files found.
std::vector<cv::Mat> load_user_masks(const std::filesystem::path& dir,
                                     const std::vector<std::string>& names, cv::Size size,
                                     int* frames_with_masks = nullptr);

// Clears pixels of a flow-pair validity mask (CV_8U, flow a -> b at the masks' size) that lie in
// an ignored region of a, or whose flow target x + F_ab(x) touches an ignored pixel of b (any of
// the four pixels bilinear sampling reads). Returns the number of pixels cleared.
long long apply_user_masks(cv::Mat& flow_mask, const cv::Mat& flow_ab, const cv::Mat& usable_a,
                           const cv::Mat& usable_b);

}  // namespace cvd
