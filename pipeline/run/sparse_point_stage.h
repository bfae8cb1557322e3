// Stage 5 of run_pipeline: the sparse 3-D points that start the default network (warm-up) or
// calibrate a converted one's scale. SfM's points when the pose stage made some; otherwise (poses
// given by the user) points triangulated from flow tracks through the consecutive-frame flows,
// one point per track so that the frames' sparse depths share one scale, or pair by pair when no
// track could be triangulated; without any point, a depth level from the flow and the poses.
#pragma once
#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <vector>

#include "pipeline/run/run_stages.h"

namespace cvd {

struct SparsePointsStage {
  std::vector<std::vector<Eigen::Vector3d>> points;  // per frame: the points it observes
  bool from_sfm = false;
  nlohmann::json triangulation;  // how flow points were made (null for SfM points)
  // Where not one point could be made: the depth level of the flow's pixels in the poses' units
  // (pipeline/geometry/flow_depth_level.h), the default network's flat start; 0 otherwise.
  double fallback_depth = 0.0;
};

// `cams` at the depth resolution; `usable` the user masks at that resolution (empty: none).
SparsePointsStage run_sparse_points_stage(const PosesStage& poses, const FlowStage& flow,
                                          const std::vector<NamedCamera>& cams,
                                          const std::vector<cv::Mat>& usable);

}  // namespace cvd
