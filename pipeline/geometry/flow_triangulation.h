// Sparse 3-D points from optical flow and known cameras, for runs whose poses come from the user
// (no SfM points): each trusted flow correspondence of a pair is triangulated (midpoint of the
// two rays) and kept when it has enough parallax, lies in front of both cameras and reprojects
// within a pixel. The points feed scale calibration and the initial depth level.
#pragma once
#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <vector>

#include "pipeline/geometry/camera.h"

namespace cvd {

struct FlowTriangulationOptions {
  int grid_step = 6;              // sample every n-th pixel in x and y
  double min_parallax_deg = 1.0;  // angle between the two rays
  double max_reprojection_px = 1.0;
};

// flow: CV_32FC2 from frame i to j at the cameras' intrinsics resolution; mask: CV_8U (non-zero
// = trusted). Appends each kept point to points[i] and points[j] (world coordinates).
int triangulate_flow_points(const NamedCamera& ci, const NamedCamera& cj, int i, int j,
                            const cv::Mat& flow, const cv::Mat& mask,
                            std::vector<std::vector<Eigen::Vector3d>>& points,
                            const FlowTriangulationOptions& options = {});

}  // namespace cvd
