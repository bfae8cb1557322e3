// The depth level of a clip whose flow could not be triangulated into any sparse point (given
// poses with a tiny baseline, or cameras that disagree with the flow): the default network then
// starts as a flat plane at this level, in the units of the poses. Each trusted flow
// correspondence of a pair gives the inverse depth of its pixel along the ray of the first frame
// in closed form (the projection into the second frame is linear in inverse depth), with a
// sensitivity (how far the projection moves per unit of inverse depth: the pair's baseline as
// seen from that pixel); the level is 1 / the sensitivity-weighted median of those inverse
// depths, so noise in a small parallax shifts it little. Where that median is not positive (pure
// rotation, or cameras the flow contradicts), the level is the nearest depth at which the clip's
// widest baseline subtends `no_parallax_deg` (the triangulation's parallax threshold: nothing
// was kept, so the scene is at least that far), or 1 without any baseline.
#pragma once
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "pipeline/geometry/camera.h"

namespace cvd {

// Inverse-depth samples of one frame's pixels, gathered over pairs.
struct InverseDepthSamples {
  std::vector<double> inverse_depth;  // 1 / z in frame i's camera, signed (noise can make it < 0)
  std::vector<double> weight;         // sensitivity^2 (normalised image units per inverse depth)
};

// Adds a sample per trusted flow pixel on a grid (every `grid_step` pixels) of the pair i -> j.
// flow: CV_32FC2 at the cameras' intrinsics resolution; mask: CV_8U, non-zero = trusted.
void add_inverse_depth_samples(const NamedCamera& ci, const NamedCamera& cj, const cv::Mat& flow,
                               const cv::Mat& mask, InverseDepthSamples& samples,
                               int grid_step = 4);

struct FlowDepthLevel {
  double depth = 1.0;
  std::string source;  // "flow" (the weighted median) or "baseline" or "none"
  nlohmann::json info() const;
  double widest_baseline = 0.0;  // the largest distance between two registered cameras
  double median_inverse_depth = 0.0;
  size_t samples = 0;
};

FlowDepthLevel flow_depth_level(const InverseDepthSamples& samples,
                                const std::vector<NamedCamera>& cams, double no_parallax_deg = 1.0);

}  // namespace cvd
