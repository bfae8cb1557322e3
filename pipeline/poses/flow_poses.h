// Cameras from optical flow alone, for clips COLMAP cannot pose (too little parallax for an
// initial pair, too few features) or when the user asks for them (`--poses-source flow`).
// Consecutive frames get forward and backward DIS flow at a working resolution; pixels whose two
// flows agree are followed into tracks (pipeline/geometry/flow_tracks.h); rotations are chained
// from the tracks and centres solved given them (pipeline/poses/flow_camera_init.h); then one
// robust bundle adjustment of every camera, the focal and one point per track
// (pipeline/poses/track_bundle_adjustment.h). The adjustment starts from several guesses (each
// candidate field of view, with its focal free, when the intrinsics are unknown; rotations chained
// from essential matrices or from rotation-only fits, whichever the parallax favours), each
// adjusted on a subset of the tracks, and the one ending with the lowest truncated reprojection
// error wins (the loss decides, not a point count). The result is a COLMAP-style model (cameras,
// and the points with their observations) at the frames' resolution, so it is cached and used
// exactly like COLMAP's.
#pragma once
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "pipeline/geometry/camera.h"
#include "pipeline/geometry/flow_tracks.h"
#include "pipeline/io/trajectory_io.h"

namespace cvd {

struct FlowPoseOptions {
  int long_side = 384;  // flow and tracks at this long side (frames larger are resized)
  double forward_backward_px = 1.0;  // a pixel is tracked where forward + backward flow <= this
  FlowTrackOptions tracks = {8, 2, 24, 3, 0, 0};  // grid 8 px, start every 2nd frame, <= 24 views
  int max_tracks = 15000;                         // evenly thinned beyond this
  std::vector<double> candidate_fov_deg = {45, 60, 75, 90};  // without known intrinsics
  int candidate_tracks = 3000;                               // tracks per candidate adjustment
  int finalists = 2;  // the best candidates adjusted further on every track; the lowest error wins
  double huber_px = 1.0;
  double outlier_px = 3.0;  // observations beyond this are dropped before the last pass
  double export_px = 1.5;   // observations of exported points lie within this
  // Points exported as sparse depth: at least this many views within export_px, whose rays span
  // at least this parallax.
  double min_point_parallax_deg = 2.0;
  int min_point_views = 3;
  int min_frame_observations = 20;  // a frame with fewer inlier observations is unregistered
  int threads = 0;                  // 0: every hardware thread
};

struct FlowPoseCandidate {
  double start_fov_deg = 0, start_focal_px = 0, focal_px = 0;  // frames' resolution
  std::string
      rotations;     // how the first rotations were chained: "essential matrix" or "rotation fit"
  double score = 0;  // mean of min(error^2, outlier_px^2) over the subset's observations; -1 failed
  double rms_px = 0;
  // Finalists only (0 otherwise): the same after the adjustment on every track (-1 failed).
  double final_score = 0, final_focal_px = 0;
};

struct FlowPoseResult {
  std::vector<NamedCamera> cameras;       // one per frame, by name, at the frames' resolution
  ColmapModel model;                      // the same cameras, and points with observations
  std::vector<std::string> unregistered;  // frames left without a pose
  std::vector<std::string> warnings;
  std::string focal_method;    // "given" or "flow bundle adjustment"
  std::string rotation_start;  // the chaining of the start that won (FlowPoseCandidate::rotations)
  std::vector<FlowPoseCandidate> candidates;
  int tracks = 0, residuals = 0, points = 0, guessed_rotations = 0;
  double rms_px = 0;  // of the inlier observations after the last pass
  // Mean over every observation of min(error^2, outlier_px^2), px^2 at the working resolution:
  // with the start cameras and points intersected from them (start cameras only), and at the end.
  double start_score_px2 = 0, score_px2 = 0;
  double median_parallax_deg = 0;  // of the tracks' widest ray angle
  double flow_seconds = 0, adjustment_seconds = 0, seconds = 0;
};

// The tracks the cameras are estimated from: pixels followed through forward-backward consistent
// DIS flows of consecutive frames at the working resolution (pixel coordinates of work_size).
struct FlowPoseTracks {
  std::vector<PixelTrack> tracks;
  cv::Size frame_size, work_size;
  double seconds = 0;
};
FlowPoseTracks track_frames(const std::vector<std::string>& names,
                            const std::function<cv::Mat(size_t)>& frame,
                            const std::function<cv::Mat(size_t)>& mask,
                            const FlowPoseOptions& options = {});

// frame(k): frame k (BGR, every frame the same size); mask(k): CV_8U, 0 = ignore, or empty.
// K: known intrinsics at the frames' resolution, or nullopt (estimated). Throws
// Error(invalid_argument) for fewer than 2 frames or frames of different sizes, Error(external)
// when the flow gives no usable tracks at all.
// start: cameras to start from instead of the candidates (given poses, camera-to-world, one per
// frame; unregistered ones stay unregistered); needs K, keeps the start's units and adjusts the
// cameras and points on the tracks with the focal fixed.
FlowPoseResult estimate_flow_poses(const std::vector<std::string>& names,
                                   const std::function<cv::Mat(size_t)>& frame,
                                   const std::function<cv::Mat(size_t)>& mask,
                                   const std::optional<Intrinsics>& K,
                                   const FlowPoseOptions& options = {},
                                   const std::vector<NamedCamera>* start = nullptr);

}  // namespace cvd
