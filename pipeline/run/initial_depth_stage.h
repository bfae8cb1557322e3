// Stage 6 of run_pipeline: the network's depth before test-time training and how it is tied to
// the cameras' units. The default (untrained) network starts as a flat plane at the median sparse
// depth and is warmed up on the sparse depths (pipeline/training/network_start.h); converted
// weights get a scale calibration (inverse depth: one scale for the video, applied to the poses)
// or, for affine-invariant disparity (Depth Anything), a robust scale-and-shift fit set on the
// network.
#pragma once
#include <functional>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <vector>

#include "models/depth_net.h"
#include "pipeline/run/run_options.h"
#include "pipeline/run/sparse_point_stage.h"
#include "pipeline/training/network_start.h"

namespace cvd {

struct InitialDepthStage {
  std::vector<SparseDepth> sparse;  // per frame: the sparse points projected at the depth size
  std::vector<cv::Mat> depths;      // the network's depth before training (CV_32F)
  nlohmann::json calibration;       // what was done, for run.json
  // The depth unit of the training loss (GeometricLossOptions::depth_unit): 1 where the cameras
  // were calibrated to the network's units; where the network's depth takes the cameras' units
  // (the default network, affine disparity), the median sparse depth (the default network's
  // flat-plane level, its fallback level without points), so training does not depend on the
  // unit the cameras come in.
  double depth_unit = 1.0;
};

// `cams` at the depth resolution; a scale calibration rescales them. Several processes: rank 0
// warms the network up and the others receive its weights.
InitialDepthStage run_initial_depth_stage(const RunOptions& o, DepthNet& net,
                                          const std::function<Tensor(int)>& load_frame,
                                          const SparsePointsStage& points,
                                          std::vector<NamedCamera>& cams, cv::Size depth_size);

}  // namespace cvd
