// The network's depth of every frame of a run (eval mode, no gradients): the initial depth before
// test-time training and the final depth after it.
#pragma once
#include <functional>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "models/depth_net.h"
#include "pipeline/run/run_options.h"

namespace cvd {

// Depth maps (CV_32F at `size`) of frames 0..n-1, `load_frame(k)` giving frame k as RGB in [0, 1],
// [3, H, W]; o.progress hears `stage`. Several processes: frame k on rank k % R, then each map
// broadcast from its rank, so every process holds all of them.
std::vector<cv::Mat> infer_depths(DepthNet& net, const std::function<Tensor(int)>& load_frame,
                                  int n, cv::Size size, const RunOptions& o,
                                  const std::string& stage);

}  // namespace cvd
