// Bundle adjustment of cameras, one shared focal length and 3-D points on pixel tracks (Ceres).
// Used by the flow-initialised cameras (pipeline/poses/flow_poses.h) for clips COLMAP cannot pose:
// every track is one 3-D point, every observation a reprojection residual under a Huber loss; the
// first usable frame is held fixed and the distance of one far camera from it is held by a prior
// (the scale gauge); the focal is a parameter when it is unknown, bounded to a plausible field of
// view. Principal point fixed, no distortion.
#pragma once
#include <Eigen/Core>
#include <vector>

#include "pipeline/geometry/flow_tracks.h"

namespace cvd {

// Cameras as the adjustment sees them: camera-to-world rotations and centres (camera.h
// convention), pinhole with fx = fy = focal, principal point (cx, cy), pixels of the tracks.
struct TrackCameras {
  std::vector<Eigen::Matrix3d> R;
  std::vector<Eigen::Vector3d> c;
  double focal = 0, cx = 0, cy = 0;
  int width = 0, height = 0;
};

struct TrackBundleOptions {
  bool refine_focal = false;
  double huber_px = 1.0;    // robust loss scale
  int max_iterations = 40;  // per pass
  // > 0: a second pass without the observations the first left beyond this many pixels.
  double outlier_px = 3.0;
  double min_fov_deg = 20;  // focal bounds (horizontal field of view)
  double max_fov_deg = 120;
  int threads = 0;  // 0: every hardware thread
};

struct TrackBundleReport {
  double initial_cost = 0, final_cost = 0;  // Ceres costs (robustified, 1/2 sum)
  double rms_px = 0;  // root mean square reprojection error over the last pass's residuals
  int residuals = 0, iterations = 0;
  int outliers = 0;     // observations left out of the second pass
  bool usable = false;  // Ceres reported a usable solution
};

// Adjusts cams (frames with usable[k]) and points[t] (one per track) in place. Observations of
// unusable frames are ignored. Throws Error(invalid_argument) for mismatched sizes.
TrackBundleReport bundle_adjust_tracks(const std::vector<PixelTrack>& tracks,
                                       const std::vector<bool>& usable,
                                       std::vector<Eigen::Vector3d>& points, TrackCameras& cams,
                                       const TrackBundleOptions& options = {});

// Reprojection error of track t's point in observation i (pixels; +inf behind the camera).
double reprojection_error_px(const TrackCameras& cams, const Eigen::Vector3d& X,
                             const PixelTrack::Observation& ob);

}  // namespace cvd
