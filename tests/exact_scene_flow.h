// Exact optical flow of the generated scene (scene/synthetic_scene.h) from its depth and poses,
// for tests of what the pipeline builds on flow (tracks, the epipolar check).
#pragma once
#include <opencv2/core.hpp>

#include <cstddef>

#include "scene/synthetic_scene.h"

namespace cvd::test {

// Flow a -> b of frame a's pixels (CV_32FC2) and the mask (CV_8U, 255) of the trusted ones: static
// scene (not the moving object), inside frame b and seen there (not occluded: frame b's depth at
// the landing pixel matches within 1%).
void exact_scene_flow(const SyntheticScene& s, size_t a, size_t b, cv::Mat& flow, cv::Mat& mask);

}  // namespace cvd::test
