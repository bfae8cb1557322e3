// Sparse 3-D points from flow tracks and known cameras, for runs whose poses come from the user
// (no SfM points). Pixels on a grid are followed through the consecutive-frame flows (i -> i+1,
// trusted pixels only) into tracks of several frames; each track is triangulated once from all
// its rays (least-squares point closest to every ray) and kept when its rays span enough parallax,
// the point lies in front of every camera and reprojects within a pixel or so in every frame. The
// one point is then an observation of every frame of its track, so the frames' sparse depths share
// one scale, unlike points triangulated pair by pair, whose scale drifts from frame to frame.
#pragma once
#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <vector>

#include "pipeline/geometry/camera.h"

namespace cvd {

struct FlowTrackOptions {
  int grid_step = 6;                 // start pixels every n-th pixel in x and y
  int start_every = 2;               // start tracks in every n-th frame
  int max_length = 16;               // frames per track at most
  int min_views = 3;                 // frames per track at least
  double min_parallax_deg = 1.5;     // widest angle between two of the track's rays
  double max_reprojection_px = 1.5;  // in every frame of the track
};

// One pixel followed through consecutive frames: frames[i] sees it at (x[i], y[i]), frames
// consecutive and increasing.
struct PixelTrack {
  struct Observation {
    int frame;
    double x, y;
  };
  std::vector<Observation> observations;
};

// Follows pixels on a grid (every options.grid_step pixels, started in every start_every-th frame
// with a flow) through the flows, sub-pixel, while every pixel the bilinear sample reads is trusted
// and the position stays in the image; keeps tracks of at least min_views and at most max_length
// frames. usable[k] == false ends tracks at frame k (empty = every frame usable).
std::vector<PixelTrack> follow_flow_tracks(const std::vector<cv::Mat>& next_flow,
                                           const std::vector<cv::Mat>& next_mask,
                                           const std::vector<bool>& usable,
                                           const FlowTrackOptions& options);

struct FlowTrackStats {
  int tracks = 0;      // tracks of at least min_views frames
  int kept = 0;        // triangulated and kept
  int max_length = 0;  // the longest track allowed (frames)
};

// next_flow[k] / next_mask[k]: the flow from frame k to k + 1 (CV_32FC2, pixels at the cameras'
// resolution) and its trusted pixels (CV_8U, non-zero = trusted); empty where that pair is
// missing. Appends each kept point to points[k] for every frame k of its track.
FlowTrackStats triangulate_flow_tracks(const std::vector<NamedCamera>& cams,
                                       const std::vector<cv::Mat>& next_flow,
                                       const std::vector<cv::Mat>& next_mask,
                                       std::vector<std::vector<Eigen::Vector3d>>& points,
                                       const FlowTrackOptions& options = {});

// A slow clip (many frames to little motion: a long recording, a high frame rate) sees too little
// parallax within options.max_length frames for any track to be kept. While fewer than
// `min_kept` tracks are kept, this tries tracks 4x and then 16x as long, started 4x and 16x less
// often (about the same work and memory), and keeps the points of the attempt that kept the most;
// stats.max_length says which. Drifting long tracks fail the reprojection check like any other.
FlowTrackStats triangulate_flow_tracks_lengthening(
    const std::vector<NamedCamera>& cams, const std::vector<cv::Mat>& next_flow,
    const std::vector<cv::Mat>& next_mask, std::vector<std::vector<Eigen::Vector3d>>& points,
    int min_kept, const FlowTrackOptions& options = {});

}  // namespace cvd
