// The sparse 3-D points a run started from (COLMAP's, or triangulated from flow when the poses
// were given), judged against GT depth: how dense they are and how accurate, so a table can set
// the dense network output beside the SfM points it was calibrated on.
// The file and its reader: pipeline/io/sparse_depth_io.h.
#pragma once
#include <opencv2/core.hpp>

#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "pipeline/io/sparse_depth_io.h"

namespace cvd {

struct SparseDepthEval {
  int frames = 0;            // frames with >= 1 point on valid GT
  int64_t points = 0;        // points on valid GT, all frames
  double density = 0;        // mean over frames of points / pixels of the depth map
  double abs_rel = 0;        // mean over frames of mean |s z - d| / d, s = median(d / z) per frame
  double abs_rel_video = 0;  // the same with ONE s (median over all points) for the whole video
  double delta1 = 0;         // fraction of points with max(s z / d, d / s z) < 1.25 (per-frame s)
};

// `gt_depths[i]` (metres, <= 0 or non-finite invalid) is the GT of frame `names[i]`; points are
// looked up at the nearest GT pixel after scaling (u, v) from the point's resolution to the GT's
// (pixel centres map onto pixel centres). Frames without points are skipped.
SparseDepthEval evaluate_sparse_depth(const std::map<std::string, SparseDepthFrame>& sparse,
                                      const std::vector<std::string>& names,
                                      const std::vector<cv::Mat>& gt_depths, double min_depth,
                                      double max_depth);

}  // namespace cvd
