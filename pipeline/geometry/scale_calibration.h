// Scale calibration (paper section 4.1): brings the structure-from-motion poses into the units of
// the depth network's initial depth maps.
//
// Convention (kept by every function here):
//   s_i = median over the sparse SfM points observed in frame i of  D_NN(x) / D_SfM(x),
// where D_SfM(x) is the point's depth in camera i and D_NN(x) the network depth sampled at the
// point's projection x. So s_i > 1 means the network's units are larger than the SfM units.
//   s = mean of s_i over the valid frames,   t_i <- s * t_i  (camera centres, camera-to-world).
// After this, a network depth map back-projected with the scaled pose agrees with the other
// frames' scaled poses. The reference implementation stores the inverse ratio (D_SfM / D_NN) and
// divides the translations by its mean; both give poses in network depth units (the two means
// differ only through the spread of the per-frame ratios).
//
// Frames with fewer than `min_points` valid samples get no s_i: they are marked invalid (to be
// excluded from the loss) but keep a scaled pose in the output.
#pragma once
#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <vector>

#include "pipeline/geometry/camera.h"
#include "pipeline/io/trajectory_io.h"

namespace cvd {

struct ScaleCalibrationOptions {
  int min_points = 10;      // fewer valid samples in a frame -> the frame is invalid
  double min_depth = 1e-6;  // depths at or below this (either map) are not valid samples
};

struct ScaleCalibrationResult {
  std::vector<double> frame_scales;      // s_i; NaN where the frame is invalid
  std::vector<int> frame_sample_counts;  // valid samples behind each s_i
  std::vector<bool> frame_valid;
  double scale = 0.0;                // s, the mean of the valid s_i
  std::vector<NamedCamera> cameras;  // the input cameras with t <- s * t
  int num_valid() const;
};

// cameras[i], depths[i] and observed_points[i] belong to frame i. depths: CV_32FC1 or CV_64FC1
// network depth, any resolution (the intrinsics are rescaled to it); 0 or negative = no depth.
// observed_points: world coordinates (SfM units) of the sparse points frame i observes.
// Unregistered cameras are invalid frames. Throws Error(numerical) when no frame is valid.
ScaleCalibrationResult calibrate_scale(
    const std::vector<NamedCamera>& cameras, const std::vector<cv::Mat>& depths,
    const std::vector<std::vector<Eigen::Vector3d>>& observed_points,
    const ScaleCalibrationOptions& options = {});

// Same, with the points each frame observes taken from a COLMAP model by the camera's NAME.
ScaleCalibrationResult calibrate_scale(const std::vector<NamedCamera>& cameras,
                                       const std::vector<cv::Mat>& depths, const ColmapModel& model,
                                       const ScaleCalibrationOptions& options = {});

}  // namespace cvd
