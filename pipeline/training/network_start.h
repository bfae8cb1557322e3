// How the default (untrained) network starts test-time training, so that the start can only
// help: its output head is zeroed, making the first prediction a flat plane at the median sparse
// depth, and the warm-up on the sparse depths is kept only as far as it beats that plane on
// frames it did not train on (paper section 4 leaves the initial depth to a pretrained network;
// the default network has none).
#pragma once
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "engine/tensor.h"
#include "models/depth_net.h"

namespace cvd {

// Projected sparse points of one frame: pixel (u, v) at the depth resolution and depth z.
struct SparseDepth {
  std::vector<double> u, v, z;
};

// The disparity weight lambda of the geometric loss for a network started here (no converted
// weights), whose depth unit is the median sparse depth (GeometricLossOptions::depth_unit). The
// architectures' own lambdas are in a converted network's depth units. Chosen on the 7-Scenes
// kitchen clips at the 4-epoch benchmark settings (README, "The loss's depth unit"): 0.01 best
// of 0.001, 0.01 and 0.1 with COLMAP's cameras on frames 0-149 every 3rd and ground-truth poses
// on frames 0-39.
inline constexpr double kUntrainedNetworkLambda = 0.01;

struct NetworkStartOptions {
  int warmup_steps = 200;  // 0: the flat plane, no warm-up
  double lr = 4e-4;        // Adam, as test-time training
  uint64_t seed = 0;
  // Depth of the flat plane when there are no sparse points at all (given poses with a tiny
  // baseline): in the units of the poses. The pipeline sets the level of the flow's pixels
  // (pipeline/geometry/flow_depth_level.h).
  double fallback_depth = 1.0;
  // Fit each frame's sparse depths up to one scale factor per frame (for points triangulated
  // from flow, whose scale drifts from frame to frame); otherwise absolute log depth.
  bool scale_free_per_frame = false;
  // Called after every warm-up step with (step, steps, detail).
  std::function<void(int, int, const std::string&)> progress;
};

// Sets `net`'s starting state: output head zero and its bias at the median sparse depth (the
// flat plane), then the warm-up, checked every few steps on held-out sparse depths (every 4th
// frame that has points, or every n-th where that keeps at most 64 frames; every 5th point when
// fewer than 4 frames have any). The state with the lowest held-out error, the flat plane
// included, is the one kept. `load_frame(k)` gives frame k as RGB in [0, 1], [3, H, W]. Returns what was done for run.json; `warnings` gets a line when
// there were no sparse points.
nlohmann::json start_default_network(DepthNet& net, const std::function<Tensor(int)>& load_frame,
                                     const std::vector<SparseDepth>& sparse,
                                     const NetworkStartOptions& o,
                                     std::vector<std::string>* warnings = nullptr);

}  // namespace cvd
