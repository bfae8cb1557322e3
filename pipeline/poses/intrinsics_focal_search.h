// Choosing a focal length from the frames alone, when neither the user nor the file gives one.
//
// COLMAP with a free focal on a short hand-held clip is unreliable: the focal is nearly
// unobservable at low parallax, and on the 7-Scenes test clip COLMAP converged to 2.4x the true
// focal and split the clip (README, "Camera intrinsics"). Instead, features are extracted and
// matched once, then the mapper is run with each of a few candidate focals HELD FIXED (the
// database's camera is edited between runs, pipeline/poses/intrinsics_colmap_database.h), each run is
// scored here, and the best one is refined by a bundle adjustment with the focal free
// (pipeline/poses/colmap_runner.cpp).
#pragma once
#include <string>
#include <vector>

#include "pipeline/io/trajectory_io.h"

namespace cvd {

// Focal length in pixels of a camera `width` pixels wide with horizontal field of view `fov_deg`.
double focal_from_fov(int width, double fov_deg);
// Horizontal field of view in degrees of focal `focal_px` on an image `width` pixels wide.
double fov_from_focal(int width, double focal_px);

// What one mapper run with a fixed focal produced.
struct FocalCandidate {
  double focal_px = 0;  // at the frames' resolution
  double fov_x_deg = 0;
  int registered = 0;  // frames in the largest model
  int num_models = 0;
  int points = 0;                      // 3-D points of the largest model
  double mean_reprojection_error = 0;  // px at COLMAP's resolution, over the largest model's points
  double seconds = 0;
};

// Mean reprojection error of a model (each point's error weighted by its track length, as
// COLMAP reports it); 0 for a model without points.
double mean_reprojection_error(const ColmapModel& model);

// Index of the best candidate: most registered frames; then fewest models (a focal far too long
// splits the clip into many small models); then most 3-D points when the counts differ by more
// than 10% (the right focal triangulates the most matches consistently: on the 7-Scenes clip
// 3401 points at f = 554 px against 886 at f = 381 px, both 40/40 frames in one model); then the
// lowest mean reprojection error. Reprojection error alone is NOT a usable criterion: the too-short
// 381 px had the lower error (0.72 against 0.83 px), its few surviving points being the easy ones.
// -1 when none registered anything.
int best_focal_candidate(const std::vector<FocalCandidate>& candidates);

// A plausibility check of a focal for an image size: empty when the horizontal field of view is
// within [min_fov_deg, max_fov_deg], else a warning naming the focal and the field of view.
std::string implausible_focal_warning(double focal_px, int width, int height,
                                      double min_fov_deg = 25.0, double max_fov_deg = 120.0);

}  // namespace cvd
