// Colour coding of dense flow with the Middlebury colour wheel (Baker et al., IJCV 2011): hue =
// direction, saturation = magnitude relative to `max_radius`; unknown (non-finite or |u|,|v| >=
// 1e9) pixels are black. Write the image with write_image (pipeline/io/image_io.h).
#pragma once
#include <opencv2/core.hpp>

namespace cvd {

// CV_8UC3 BGR image of the flow's size. max_radius <= 0: the largest known magnitude (at least
// 1e-6) of this flow; vectors longer than max_radius are drawn darkened (x0.75).
cv::Mat flow_to_color(const cv::Mat& flow, float max_radius = 0.f);

// The RGB colour (components in [0, 1]) of the wheel for flow (u, v) already divided by the
// maximum radius; exposed for tests.
cv::Vec3f flow_wheel_color_rgb(float u, float v);

}  // namespace cvd
