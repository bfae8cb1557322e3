// How far a pair's optical flow lies from the epipolar geometry of its two cameras, and which
// pairs of a clip contradict their cameras.
//
// The geometric loss asks every pair's flow to be explained by one depth map and the two cameras.
// The epipolar constraint needs no depth: a flow vector x -> x' of a static point satisfies
// x'^T F x = 0 for the pair's fundamental matrix F, whatever the point's depth. Its Sampson
// distance (the first-order distance, in pixels, of the correspondence from the constraint) is
// flow noise where the cameras are right and grows with their error where they are not: a pose
// glitch between two frames (7-Scenes documents one between frames 121 and 122) makes the pairs
// across it unsatisfiable for any depth.
#pragma once
#include <opencv2/core.hpp>

#include <vector>

#include "pipeline/geometry/camera.h"

namespace cvd {

// Median Sampson distance in pixels of the flow a -> b (CV_32FC2, pixel (x, y) of a moves to
// (x + u, y + v) in b) over the pixels where `mask` (CV_8U, same size; empty: every pixel) is
// non-zero, sampled every `stride` pixels in x and y. The cameras' intrinsics must be those of
// the flow's resolution. Where the two camera centres coincide the constraint is vacuous, so
// the distance is that of the rotation's homography transfer instead. Returns a negative value
// when no pixel is sampled.
double median_epipolar_distance(const cv::Mat& flow, const cv::Mat& mask, const NamedCamera& a,
                                const NamedCamera& b, int stride = 2);

struct EpipolarCheckOptions {
  // A pair is dropped when its distance exceeds both `factor` times the median over the pairs
  // and `floor_fraction` of the image's long side (at 192 px: 0.77 px).
  double factor = 3.0;
  double floor_fraction = 0.004;
  // At most this fraction of the pairs is dropped (the worst ones): cameras that contradict
  // most of the flow are a problem of the cameras, not of a few pairs, and training keeps going.
  double max_dropped_fraction = 0.25;
};

struct EpipolarCheck {
  double median_px = 0;     // over the pairs with a distance
  double threshold_px = 0;  // pairs above it are dropped (up to the cap)
  std::vector<bool> drop;   // per pair, in the order given
  int capped = 0;           // pairs above the threshold kept because of the cap
};

// Decides which pairs to drop from their distances (negative: unknown, never dropped) and the
// long side of the flows' images in pixels.
EpipolarCheck check_epipolar_distances(const std::vector<double>& distances_px, int long_side_px,
                                       const EpipolarCheckOptions& options = {});

}  // namespace cvd
