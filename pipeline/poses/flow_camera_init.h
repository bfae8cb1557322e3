// A first guess of cameras and points from pixel tracks alone, for the bundle adjustment of
// pipeline/poses/track_bundle_adjustment.h: rotations chained between consecutive frames (a
// rotation fit or the essential matrix, whichever the pair's parallax calls for), then the camera centres
// that best explain every track given those rotations (the linear "known rotation" problem: the
// points eliminated in closed form, the centres the smallest eigenvector of the reduced quadratic
// form, sparse, found by inverse iteration), then each track's point as the least-squares
// intersection of its rays.
#pragma once
#include <Eigen/Core>
#include <vector>

#include "pipeline/geometry/flow_tracks.h"
#include "pipeline/poses/track_bundle_adjustment.h"

namespace cvd {

// Unit ray of pixel (x, y) in camera coordinates.
Eigen::Vector3d camera_ray(const TrackCameras& cams, double x, double y);

// cams.R gets the chained rotations (frame 0 of the chain: identity). Each link: the rotation
// alone where it explains the pair within rotation_only_px (median; 0: never, infinity: always),
// else the essential matrix's.
// Frames with fewer than min_matches correspondences to the previous usable frame keep the
// previous rotation and are counted in the return value (links that were guessed).
int chain_rotations(const std::vector<PixelTrack>& tracks, const std::vector<bool>& usable,
                    TrackCameras& cams, int min_matches = 30, double rotation_only_px = 0.0);

// cams.c from cams.R (centre of the first usable frame at the origin, unit RMS distance of the
// others from it; the sign that puts most points in front of the cameras). False when the tracks
// do not determine them (then every centre is left at the origin).
bool centres_from_rotations(const std::vector<PixelTrack>& tracks, const std::vector<bool>& usable,
                            TrackCameras& cams);

// Least-squares intersection of each track's rays (observations in usable frames only); the
// widest angle between two of its rays (degrees) in parallax_deg when given.
std::vector<Eigen::Vector3d> intersect_track_rays(const std::vector<PixelTrack>& tracks,
                                                  const std::vector<bool>& usable,
                                                  const TrackCameras& cams,
                                                  std::vector<double>* parallax_deg = nullptr);

// Moves every point that lies behind a camera observing it onto the first observation's ray at
// the median depth of the other points (the adjustment cannot start from a point behind a camera).
// Returns how many were moved.
int place_points_in_front(const std::vector<PixelTrack>& tracks, const std::vector<bool>& usable,
                          const TrackCameras& cams, std::vector<Eigen::Vector3d>& points);

}  // namespace cvd
